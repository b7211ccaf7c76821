# Simulated kite photography of a twin site (issue 4): the flight, the rendered photos,
# the GCP measurements and the GPS logs. Twin sites only; reads the twin's truth because it
# *creates* the observations (it is the simulated camera), never to evaluate anything.

FLIGHT = config.get("flight", {})
# Each rule gets only the flight keys it reads (the params rerun trigger): rendering, GCP
# digitising, coverage and figure settings do not rerun the flight simulation.
FLIGHT_RENDER_KEYS = ("camera", "render", "gcps", "coverage")
FLIGHT_FIGURE_KEYS = ("wind_from_deg", "wind_speed_m_s", "line_lengths_m", "figures")
FLIGHT_SIMULATE_EXCLUDE = ("render", "gcps", "coverage", "figures", "threads")
# Per survey epoch (issue 17): the section with flight.epochs.epoch<n> merged in (common.smk).
FLIGHT_SIMULATE = epoch_section("flight", exclude=FLIGHT_SIMULATE_EXCLUDE)
# the line model of the tether section, for the kite's offset from the operator
FLIGHT_TETHER = {
    k: config["tether"][k] for k in ("lines", "kites", "kite_model", "atmosphere", "segment_length_m")
    if k in config.get("tether", {})
}


rule flight_simulate:
    input:
        site=result("twin", "site.json"),
        dtm=eresult("twin", "truth/dtm.tif"),
    output:
        poses=eresult("flight", "truth/poses.csv"),
        camera_track=eresult("flight", "truth/camera_track.csv"),
        operator_track=eresult("flight", "truth/operator_track.csv"),
        camera_gpx=eresult("flight", "observed/camera_gps.gpx"),
        operator_gpx=eresult("flight", "observed/operator_gps.gpx"),
        camera_gps_csv=eresult("flight", "observed/camera_gps.csv"),
        operator_gps_csv=eresult("flight", "observed/operator_gps.csv"),
        strips=eresult("flight", "flight_strips.csv"),
    params:
        flight=FLIGHT_SIMULATE,
        tether=FLIGHT_TETHER,
        seed=config["seed"],
        epoch=epoch_number,
        crs=config["site"]["crs"],
    log:
        elogfile("flight", "flight_simulate"),
    script:
        "../scripts/flight_simulate.py"


rule flight_render:
    input:
        site=result("twin", "site.json"),
        poses=eresult("flight", "truth/poses.csv"),
        dsm=eresult("twin", "truth/dsm.tif"),
        texture=eresult("twin", "truth/texture.tif"),
        targets=eresult("twin", "truth/targets.csv"),
        survey=eresult("twin", "observed/gcp_survey.csv"),
    output:
        images=directory(eresult("flight", "observed/images")),
        gcp_list=eresult("flight", "observed/gcp_list.txt"),
        camera=eresult("flight", "truth/camera.json"),
        gcp_pixels=eresult("flight", "truth/gcp_pixels.csv"),
        coverage=eresult("flight", "images_per_ground_point.tif"),
        image_stats=eresult("flight", "image_stats.csv"),
        summary=report(
            eresult("flight", "flight_summary.csv"),
            caption=caption("flight_summary"),
            category="Flight",
        ),
    params:
        flight=epoch_section("flight", keys=FLIGHT_RENDER_KEYS),
        seed=config["seed"],
        epoch=epoch_number,
        crs=config["site"]["crs"],
    threads: FLIGHT.get("threads", 2)
    log:
        elogfile("flight", "flight_render"),
    benchmark:
        ebenchfile("flight", "flight_render")
    script:
        "../scripts/flight_render.py"


rule flight_figures:
    input:
        site=result("twin", "site.json"),
        camera=eresult("flight", "truth/camera.json"),
        poses=eresult("flight", "truth/poses.csv"),
        image_stats=eresult("flight", "image_stats.csv"),
        operator_track=eresult("flight", "truth/operator_track.csv"),
        survey=eresult("twin", "observed/gcp_survey.csv"),
        gcp_list=eresult("flight", "observed/gcp_list.txt"),
        images=eresult("flight", "observed/images"),
    output:
        flight_map=report(eresult("flight", "flight_map.png"), caption=caption("flight_map"), category="Flight"),
        samples=report(eresult("flight", "sample_images.png"), caption=caption("flight_samples"), category="Flight"),
    params:
        flight=epoch_section("flight", keys=FLIGHT_FIGURE_KEYS),
    log:
        elogfile("flight", "flight_figures"),
    script:
        "../scripts/flight_figures.py"


if IS_TWIN and "flight" in config:
    add_targets(
        epoch_results("flight", "observed/gcp_list.txt"),
        epoch_results("flight", "observed/camera_gps.gpx"),
        epoch_results("flight", "observed/operator_gps.gpx"),
        epoch_results("flight", "flight_summary.csv"),
        epoch_results("flight", "flight_map.png"),
        epoch_results("flight", "sample_images.png"),
    )
