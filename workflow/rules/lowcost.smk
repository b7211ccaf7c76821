# The low-cost kite survey of paper 004 (issue 18): twin with RGB + NIR flights, camera
# spectral response, joint SfM, tape + Horn + tide georeferencing, mosaics, NDVI, slope,
# aspect; evaluation against the twin's truth. Only sites with a `lowcost` section
# (config/sites/lowcost_twin.yaml; `make lowcost`).

if "lowcost" in config:
    LOWCOST = config["lowcost"]
    if not IS_TWIN:
        raise WorkflowError("lowcost: only twin sites are supported so far (config/sites/lowcost_twin.yaml)")

    rule lowcost_twin:
        output:
            observed=directory(result("lowcost", "twin/observed")),
            truth=directory(result("lowcost", "twin/truth")),
        params:
            twin=LOWCOST["twin"],
            seed=config["seed"],
            crs=config["site"]["crs"],
        log:
            logfile("lowcost", "lowcost_twin"),
        benchmark:
            benchfile("lowcost", "lowcost_twin")
        threads: 2
        script:
            "../scripts/lowcost_twin.py"

    rule lowcost_spectral:
        output:
            curves=report(result("lowcost", "spectral_response.csv"), caption=caption("lowcost_spectral"), category="Low-cost survey"),
            peaks=report(result("lowcost", "spectral_peaks.csv"), caption=caption("lowcost_spectral"), category="Low-cost survey"),
            figure=report(result("lowcost", "spectral_response.png"), caption=caption("lowcost_spectral"), category="Low-cost survey"),
        params:
            spectral=LOWCOST["spectral"],
            seed=config["seed"],
        log:
            logfile("lowcost", "lowcost_spectral"),
        script:
            "../scripts/lowcost_spectral.py"

    LOWCOST_SURVEY = ["matches_by_pair_type.csv", "georef_residuals.csv", "georef.json", "survey.json", "dsm.tif", "dsm_tin.tif",
                      "rgb_orthomosaic.tif", "nir_orthomosaic.tif", "ndvi.tif", "exg.tif", "slope.tif", "aspect.tif"]

    rule lowcost_survey:
        input:
            observed=rules.lowcost_twin.output.observed,
        output:
            sfm=directory(result("lowcost", "sfm")),
            **{Path(n).stem + "_" + Path(n).suffix[1:]: result("lowcost", n) for n in LOWCOST_SURVEY},
        params:
            sfm=LOWCOST["sfm"],
            survey=LOWCOST["survey"],
            seed=config["seed"],
            crs=config["site"]["crs"],
        log:
            logfile("lowcost", "lowcost_survey"),
        benchmark:
            benchfile("lowcost", "lowcost_survey")
        threads: 1 if LOWCOST["sfm"]["deterministic"] else LOWCOST["sfm"]["threads"]
        script:
            "../scripts/lowcost_survey.py"

    rule lowcost_rtk_bundle:
        input:
            observed=rules.lowcost_twin.output.observed,
            sfm=rules.lowcost_survey.output.sfm,
        output:
            folder=directory(result("lowcost", "rtk_bundle")),
        params:
            georef=LOWCOST["rtk_bundle"],
            seed=config["seed"],
            crs=config["site"]["crs"],
        log:
            logfile("lowcost", "lowcost_rtk_bundle"),
        benchmark:
            benchfile("lowcost", "lowcost_rtk_bundle")
        script:
            "../scripts/lowcost_rtk_bundle.py"

    rule lowcost_bare_soil:
        input:
            rgb=result("lowcost", "rgb_orthomosaic.tif"),
            nir=result("lowcost", "nir_orthomosaic.tif"),
            dsm=result("lowcost", "dsm.tif"),
        output:
            ndvi=result("lowcost", "bare_soil_ndvi.tif"),
            exg=result("lowcost", "bare_soil_exg.tif"),
            thresholds=result("lowcost", "bare_soil_thresholds.csv"),
        params:
            bare_soil=LOWCOST["bare_soil"],
        log:
            logfile("lowcost", "lowcost_bare_soil"),
        benchmark:
            benchfile("lowcost", "lowcost_bare_soil")
        threads: 1
        script:
            "../scripts/lowcost_bare_soil.py"

    rule lowcost_evaluate:
        input:
            survey=[result("lowcost", n) for n in LOWCOST_SURVEY],
            bare_soil=[rules.lowcost_bare_soil.output.ndvi, rules.lowcost_bare_soil.output.exg],
            truth=rules.lowcost_twin.output.truth,
        output:
            ndvi_table=report(result("lowcost", "ndvi_by_class.csv"), caption=caption("lowcost_ndvi_by_class"), category="Low-cost survey"),
            ndvi_figure=report(result("lowcost", "ndvi_by_class.png"), caption=caption("lowcost_ndvi_by_class"), category="Low-cost survey"),
            indicators=result("lowcost", "bare_ground_indicators.csv"),
            bare_soil_obia=report(result("lowcost", "bare_soil_obia.csv"), caption=caption("lowcost_bare_soil_obia"), category="Low-cost survey"),
            georef_truth=result("lowcost", "georef_truth.csv"),
            dsm_truth=result("lowcost", "dsm_truth.csv"),
            summary=result("lowcost", "evaluation.json"),
        params:
            evaluation=LOWCOST["evaluation"],
            seed=config["seed"],
        log:
            logfile("lowcost", "lowcost_evaluate"),
        script:
            "../scripts/lowcost_evaluate.py"

    add_targets(rules.lowcost_spectral.output, rules.lowcost_survey.output, rules.lowcost_rtk_bundle.output,
                rules.lowcost_bare_soil.output, rules.lowcost_evaluate.output)
