# DEM validation (issue 6): DSM sampled at independent checkpoints (Feurer et al. 2018
# Table 3); on twin sites also DSM − truth by land cover and a profile across a gully (Fig. 10,
# Table 5). Only the twin rules here read truth/ (evaluation).

if "validate" in config and "dense" in config:

    def validate_checkpoints_file(wildcards=None):
        if IS_TWIN:
            return result("twin", "observed/checkpoints.csv")
        return config.get("inputs", {}).get("checkpoints")

    VALIDATE_TWIN_INPUTS = (
        dict(landcover=result("twin", "truth/landcover.tif"), classes=result("twin", "truth/landcover_classes.csv"))
        if IS_TWIN else {}
    )

    if validate_checkpoints_file():

        rule validate_checkpoints:
            input:
                dsm=result("dense", "dsm.tif"),
                checkpoints=INPUTS_CHECKPOINTS or validate_checkpoints_file(),  # checked copy (issue 14)
                **VALIDATE_TWIN_INPUTS,
            output:
                errors=result("validate", "checkpoint_errors.csv"),
                summary=report(result("validate", "checkpoint_summary.csv"), caption=caption("validate_checkpoint_summary"), category="DEM validation"),
                histogram=report(result("validate", "checkpoint_error_histogram.png"), caption=caption("validate_histogram"), category="DEM validation"),
                map=report(result("validate", "checkpoint_error_map.png"), caption=caption("validate_error_map"), category="DEM validation"),
                **({"groups": report(result("validate", "checkpoint_summary_by_group.csv"), caption=caption("validate_groups"), category="DEM validation")} if IS_TWIN else {}),
            params:
                validate=config_keys("validate", ("bare_classes", "histogram_bins", "error_limit_m")),
            log:
                logfile("validate", "validate_checkpoints"),
            script:
                "../scripts/validate_checkpoints.py"

        add_targets(result("validate", "checkpoint_summary.csv"), result("validate", "checkpoint_error_map.png"))

    if IS_TWIN:

        rule validate_truth:
            """Evaluation only: reads the twin's truth."""
            input:
                dsm=result("dense", "dsm.tif"),
                truth_dsm=result("twin", "truth/dsm.tif"),
                truth_dtm=result("twin", "truth/dtm.tif"),
                landcover=result("twin", "truth/landcover.tif"),
                classes=result("twin", "truth/landcover_classes.csv"),
                centrelines=result("twin", "truth/gully_centrelines.gpkg"),
            output:
                error_raster=result("validate", "dsm_minus_truth.tif"),
                by_landcover=report(result("validate", "dsm_error_by_landcover.csv"), caption=caption("validate_by_landcover"), category="DEM validation"),
                error_map=report(result("validate", "dsm_error_map.png"), caption=caption("validate_truth_map"), category="DEM validation"),
                profile=result("validate", "profile.csv"),
                profile_stats=report(result("validate", "profile_stats.csv"), caption=caption("validate_profile_stats"), category="DEM validation"),
                profile_png=report(result("validate", "profile.png"), caption=caption("validate_profile"), category="DEM validation"),
            params:
                validate=config_keys("validate", ("vegetation_classes", "error_limit_m", "figure_max_px", "profile")),
            log:
                logfile("validate", "validate_truth"),
            script:
                "../scripts/validate_truth.py"

        add_targets(result("validate", "dsm_error_by_landcover.csv"), result("validate", "profile.png"))
