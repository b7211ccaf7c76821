# Ground control (issue 5): GCP triangulation, robust similarity, bundle adjustment with the
# GCPs as weighted constraints, QA flags and leave-one-out check points.

if "georef" in config and "sfm" in config:

    def georef_gcp_file(wildcards=None):
        """GCP file: config inputs for real sites, the flight stage's gcp_list.txt for twins."""
        if IS_TWIN:
            return eresult("flight", "observed/gcp_list.txt")
        return config["inputs"]["gcp_file"]

    def georef_extra_inputs(wildcards=None):
        tape = config["georef"]["tape_file"]
        return [tape] if tape else []

    def georef_first_epoch_camera(wildcards):
        """Later epochs (issue 17): the first epoch's adjusted camera, when georef.camera_from_first_epoch."""
        if config["georef"].get("camera_from_first_epoch") and wildcards.epoch:
            return result("georef", "camera_calibration.csv")
        return []

    rule georef_adjust:
        input:
            model=eresult("sfm", "model"),
            image_info=eresult("sfm", "image_info.json"),
            gcp=INPUTS_GCP,  # the checked copy (heights in metres) of georef_gcp_file()
            extra=georef_extra_inputs(),
            camera=georef_first_epoch_camera,
        output:
            model=directory(eresult("georef", "model")),
            transform=eresult("georef", "transform.json"),
            summary=report(eresult("georef", "summary.json"), caption=caption("georef_summary"), category="Georeferencing"),
            residuals=report(eresult("georef", "gcp_residuals.csv"), caption=caption("georef_gcp_residuals"), category="Georeferencing"),
            loo=report(eresult("georef", "loo_checkpoints.csv"), caption=caption("georef_loo_checkpoints"), category="Georeferencing"),
            calibration=report(eresult("georef", "camera_calibration.csv"), caption=caption("georef_camera_calibration"), category="Georeferencing"),
            cameras=eresult("georef", "camera_positions.gpkg"),
            cloud=eresult("georef", f"sparse_cloud.{config['georef']['cloud_format']}"),
            figure=report(eresult("georef", "gcp_residuals.png"), caption=caption("georef_residual_map"), category="Georeferencing"),
        params:
            georef=config["georef"],
            sfm_frame=config["sfm"]["image_frame"],
            crs=config["site"]["crs"],
            seed=config["seed"],
            attribution=config["site"].get("attribution"),
            gcp_source=lambda w: georef_gcp_file().replace("{epoch}", w.epoch),
        threads: 2
        log:
            elogfile("georef", "georef_adjust"),
        benchmark:
            ebenchfile("georef", "georef_adjust")
        script:
            "../scripts/georef_adjust.py"

    add_targets(
        epoch_results("georef", "gcp_residuals.csv"),
        epoch_results("georef", "loo_checkpoints.csv"),
        epoch_results("georef", "gcp_residuals.png"),
        epoch_results("georef", f"sparse_cloud.{config['georef']['cloud_format']}"),
        epoch_results("georef", "camera_positions.gpkg"),
        epoch_results("georef", "camera_calibration.csv"),
    )

    if IS_TWIN:

        rule georef_evaluate:
            """Evaluation only: reads the flight truth (camera poses, image GSD)."""
            input:
                cameras=eresult("georef", "camera_positions.gpkg"),
                residuals=eresult("georef", "gcp_residuals.csv"),
                loo=eresult("georef", "loo_checkpoints.csv"),
                sfm_summary=eresult("sfm", "summary.json"),
                poses=eresult("flight", "truth/poses.csv"),
                image_stats=eresult("flight", "image_stats.csv"),
            output:
                table=report(eresult("georef", "twin_camera_errors.csv"), caption=caption("georef_twin_evaluation"), category="Georeferencing"),
                summary=eresult("georef", "twin_evaluation.json"),
            log:
                elogfile("georef", "georef_evaluate"),
            script:
                "../scripts/georef_evaluate.py"

        add_targets(epoch_results("georef", "twin_evaluation.json"))
