# Ground control (issue 5): GCP triangulation, robust similarity, bundle adjustment with the
# GCPs as weighted constraints, QA flags and leave-one-out check points.

if "georef" in config and "sfm" in config:

    def georef_gcp_file(wildcards=None):
        """GCP file: config inputs for real sites, the flight stage's gcp_list.txt for twins."""
        if IS_TWIN:
            return result("flight", "observed/gcp_list.txt")
        return config["inputs"]["gcp_file"]

    def georef_extra_inputs(wildcards=None):
        tape = config["georef"]["tape_file"]
        return [tape] if tape else []

    rule georef_adjust:
        input:
            model=result("sfm", "model"),
            image_info=result("sfm", "image_info.json"),
            gcp=INPUTS_GCP,  # the checked copy (heights in metres) of georef_gcp_file()
            extra=georef_extra_inputs(),
        output:
            model=directory(result("georef", "model")),
            transform=result("georef", "transform.json"),
            summary=report(result("georef", "summary.json"), caption=caption("georef_summary"), category="Georeferencing"),
            residuals=report(result("georef", "gcp_residuals.csv"), caption=caption("georef_gcp_residuals"), category="Georeferencing"),
            loo=report(result("georef", "loo_checkpoints.csv"), caption=caption("georef_loo_checkpoints"), category="Georeferencing"),
            calibration=report(result("georef", "camera_calibration.csv"), caption=caption("georef_camera_calibration"), category="Georeferencing"),
            cameras=result("georef", "camera_positions.gpkg"),
            cloud=result("georef", "sparse_cloud.las"),
            figure=report(result("georef", "gcp_residuals.png"), caption=caption("georef_residual_map"), category="Georeferencing"),
        params:
            georef=config["georef"],
            sfm_frame=config["sfm"]["image_frame"],
            crs=config["site"]["crs"],
            seed=config["seed"],
            attribution=config["site"].get("attribution"),
        threads: 2
        log:
            logfile("georef", "georef_adjust"),
        benchmark:
            benchfile("georef", "georef_adjust")
        script:
            "../scripts/georef_adjust.py"

    add_targets(
        result("georef", "gcp_residuals.csv"),
        result("georef", "loo_checkpoints.csv"),
        result("georef", "gcp_residuals.png"),
        result("georef", "sparse_cloud.las"),
        result("georef", "camera_positions.gpkg"),
        result("georef", "camera_calibration.csv"),
    )

    if IS_TWIN:

        rule georef_evaluate:
            """Evaluation only: reads the flight truth (camera poses, image GSD)."""
            input:
                cameras=result("georef", "camera_positions.gpkg"),
                residuals=result("georef", "gcp_residuals.csv"),
                loo=result("georef", "loo_checkpoints.csv"),
                sfm_summary=result("sfm", "summary.json"),
                poses=result("flight", "truth/poses.csv"),
                image_stats=result("flight", "image_stats.csv"),
            output:
                table=report(result("georef", "twin_camera_errors.csv"), caption=caption("georef_twin_evaluation"), category="Georeferencing"),
                summary=result("georef", "twin_evaluation.json"),
            log:
                logfile("georef", "georef_evaluate"),
            script:
                "../scripts/georef_evaluate.py"

        add_targets(result("georef", "twin_evaluation.json"))
