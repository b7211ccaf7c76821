# Simulated kite photography of a twin site (issue 4): the flight, the rendered photos,
# the GCP measurements and the GPS logs. Twin sites only; reads the twin's truth because it
# *creates* the observations (it is the simulated camera), never to evaluate anything.

FLIGHT_TWIN_READY = Path("workflow/rules/twin.smk").exists()


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
        flight=config.get("flight"),
        tether=config.get("tether"),
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
        flight=config.get("flight"),
        seed=config["seed"],
        crs=config["site"]["crs"],
    threads: config.get("flight", {}).get("threads", 2)
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
        flight=config.get("flight"),
    log:
        logfile("flight", "flight_figures"),
    script:
        "../scripts/flight_figures.py"


if IS_TWIN and FLIGHT_TWIN_READY and "flight" in config:
    add_targets(
        result("flight", "observed/gcp_list.txt"),
        result("flight", "observed/camera_gps.gpx"),
        result("flight", "observed/operator_gps.gpx"),
        result("flight", "flight_summary.csv"),
        result("flight", "flight_map.png"),
        result("flight", "sample_images.png"),
    )
