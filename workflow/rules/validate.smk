# DEM validation (issue 6): DSM sampled at independent checkpoints (Feurer et al. 2018
# Table 3); on twin sites also DSM − truth by land cover and a profile across a gully (Fig. 10,
# Table 5). Only the twin rules here read truth/ (evaluation).

if "validate" in config and "dense" in config:

    def validate_checkpoints_file(wildcards=None):
        if IS_TWIN:
            return eresult("twin", "observed/checkpoints.csv")
        return config.get("inputs", {}).get("checkpoints")

    VALIDATE_TWIN_INPUTS = (
        dict(landcover=eresult("twin", "truth/landcover.tif"), classes=eresult("twin", "truth/landcover_classes.csv"))
        if IS_TWIN else {}
    )

    if validate_checkpoints_file():

        rule validate_checkpoints:
            input:
                dsm=eresult("dense", "dsm.tif"),
                checkpoints=INPUTS_CHECKPOINTS or validate_checkpoints_file(),  # checked copy (issue 14)
                **VALIDATE_TWIN_INPUTS,
            output:
                errors=eresult("validate", "checkpoint_errors.csv"),
                summary=report(eresult("validate", "checkpoint_summary.csv"), caption=caption("validate_checkpoint_summary"), category="DEM validation"),
                histogram=report(eresult("validate", "checkpoint_error_histogram.png"), caption=caption("validate_histogram"), category="DEM validation"),
                map=report(eresult("validate", "checkpoint_error_map.png"), caption=caption("validate_error_map"), category="DEM validation"),
                **({"groups": report(eresult("validate", "checkpoint_summary_by_group.csv"), caption=caption("validate_groups"), category="DEM validation")} if IS_TWIN else {}),
            params:
                validate=config_keys("validate", ("bare_classes", "histogram_bins", "error_limit_m")),
            log:
                elogfile("validate", "validate_checkpoints"),
            script:
                "../scripts/validate_checkpoints.py"

        add_targets(epoch_results("validate", "checkpoint_summary.csv"), epoch_results("validate", "checkpoint_error_map.png"))

    if IS_TWIN:

        rule validate_truth:
            """Evaluation only: reads the twin's truth."""
            input:
                dsm=eresult("dense", "dsm.tif"),
                truth_dsm=eresult("twin", "truth/dsm.tif"),
                truth_dtm=eresult("twin", "truth/dtm.tif"),
                landcover=eresult("twin", "truth/landcover.tif"),
                classes=eresult("twin", "truth/landcover_classes.csv"),
                centrelines=eresult("twin", "truth/gully_centrelines.gpkg"),
            output:
                error_raster=eresult("validate", "dsm_minus_truth.tif"),
                by_landcover=report(eresult("validate", "dsm_error_by_landcover.csv"), caption=caption("validate_by_landcover"), category="DEM validation"),
                error_map=report(eresult("validate", "dsm_error_map.png"), caption=caption("validate_truth_map"), category="DEM validation"),
                profile=eresult("validate", "profile.csv"),
                profile_stats=report(eresult("validate", "profile_stats.csv"), caption=caption("validate_profile_stats"), category="DEM validation"),
                profile_png=report(eresult("validate", "profile.png"), caption=caption("validate_profile"), category="DEM validation"),
            params:
                validate=config_keys("validate", ("vegetation_classes", "error_limit_m", "figure_max_px", "profile")),
            log:
                elogfile("validate", "validate_truth"),
            script:
                "../scripts/validate_truth.py"

        add_targets(epoch_results("validate", "dsm_error_by_landcover.csv"), epoch_results("validate", "profile.png"))
