# Simulated kite photography of a twin site (issue 4): the flight, the rendered photos,
# the GCP measurements and the GPS logs. Twin sites only; reads the twin's truth because it
# *creates* the observations (it is the simulated camera), never to evaluate anything.

FLIGHT = config.get("flight", {})
# Each rule gets only the flight keys it reads (the params rerun trigger): rendering, GCP
# digitising, coverage and figure settings do not rerun the flight simulation.
FLIGHT_RENDER_KEYS = ("camera", "render", "gcps", "coverage")
FLIGHT_FIGURE_KEYS = ("wind_from_deg", "wind_speed_m_s", "line_lengths_m", "figures")
FLIGHT_SIMULATE = {k: v for k, v in FLIGHT.items() if k not in ("render", "gcps", "coverage", "figures", "threads")}
# the line model of the tether section, for the kite's offset from the operator
FLIGHT_TETHER = {
    k: config["tether"][k] for k in ("lines", "kites", "kite_model", "atmosphere", "segment_length_m")
    if k in config.get("tether", {})
}


rule flight_simulate:
    input:
        site=result("twin", "site.json"),
        dtm=result("twin", "truth/dtm.tif"),
    output:
        poses=result("flight", "truth/poses.csv"),
        camera_track=result("flight", "truth/camera_track.csv"),
        operator_track=result("flight", "truth/operator_track.csv"),
        camera_gpx=result("flight", "observed/camera_gps.gpx"),
        operator_gpx=result("flight", "observed/operator_gps.gpx"),
        camera_gps_csv=result("flight", "observed/camera_gps.csv"),
        operator_gps_csv=result("flight", "observed/operator_gps.csv"),
        strips=result("flight", "flight_strips.csv"),
    params:
        flight=FLIGHT_SIMULATE,
        tether=FLIGHT_TETHER,
        seed=config["seed"],
        crs=config["site"]["crs"],
    log:
        logfile("flight", "flight_simulate"),
    script:
        "../scripts/flight_simulate.py"


rule flight_render:
    input:
        site=result("twin", "site.json"),
        poses=result("flight", "truth/poses.csv"),
        dsm=result("twin", "truth/dsm.tif"),
        texture=result("twin", "truth/texture.tif"),
        targets=result("twin", "truth/targets.csv"),
        survey=result("twin", "observed/gcp_survey.csv"),
    output:
        images=directory(result("flight", "observed/images")),
        gcp_list=result("flight", "observed/gcp_list.txt"),
        camera=result("flight", "truth/camera.json"),
        gcp_pixels=result("flight", "truth/gcp_pixels.csv"),
        coverage=result("flight", "images_per_ground_point.tif"),
        image_stats=result("flight", "image_stats.csv"),
        summary=report(
            result("flight", "flight_summary.csv"),
            caption=caption("flight_summary"),
            category="Flight",
        ),
    params:
        flight={k: FLIGHT[k] for k in FLIGHT_RENDER_KEYS if k in FLIGHT},
        seed=config["seed"],
        crs=config["site"]["crs"],
    threads: FLIGHT.get("threads", 2)
    log:
        logfile("flight", "flight_render"),
    benchmark:
        benchfile("flight", "flight_render")
    script:
        "../scripts/flight_render.py"


rule flight_figures:
    input:
        site=result("twin", "site.json"),
        camera=result("flight", "truth/camera.json"),
        poses=result("flight", "truth/poses.csv"),
        image_stats=result("flight", "image_stats.csv"),
        operator_track=result("flight", "truth/operator_track.csv"),
        survey=result("twin", "observed/gcp_survey.csv"),
        gcp_list=result("flight", "observed/gcp_list.txt"),
        images=result("flight", "observed/images"),
    output:
        flight_map=report(result("flight", "flight_map.png"), caption=caption("flight_map"), category="Flight"),
        samples=report(result("flight", "sample_images.png"), caption=caption("flight_samples"), category="Flight"),
    params:
        flight={k: FLIGHT[k] for k in FLIGHT_FIGURE_KEYS if k in FLIGHT},
    log:
        logfile("flight", "flight_figures"),
    script:
        "../scripts/flight_figures.py"


if IS_TWIN and "flight" in config:
    add_targets(
        result("flight", "observed/gcp_list.txt"),
        result("flight", "observed/camera_gps.gpx"),
        result("flight", "observed/operator_gps.gpx"),
        result("flight", "flight_summary.csv"),
        result("flight", "flight_map.png"),
        result("flight", "sample_images.png"),
    )
