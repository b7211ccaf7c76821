# Change between epochs (issue 17): two epoch DEMs -> co-registration on stable ground, DoD,
# propagated uncertainty and GCD thresholds, budgets by mask, headcut retreat. A site gives its
# epochs as DEM GeoTIFFs (change.epochs); a twin site (change.epochs null) surveys both epochs
# through flight -> sfm -> georef -> dense ({epoch} wildcard, common.smk) and compares the two
# dense DSMs. Only change_evaluate reads truth (change.evaluation).

if "change" in config:

    CHANGE = dict(config["change"])
    if CHANGE["epochs"] is None:
        # Twin: the two photogrammetric DSMs, sigma from each epoch's (checked) checkpoints,
        # masks from epoch 1's gully polygons and kite bare-soil map, heads digitised at epoch 1.
        if not (IS_TWIN and SURVEY_EPOCHS == [1, 2] and "dense" in config):
            raise WorkflowError("Invalid configuration: change.epochs: null (the twin's two surveys) needs a twin site "
                                "with twin.epoch2 and the dense stage; other sites give their epochs as DEM files")
        CHANGE["epochs"] = [
            {"name": f"epoch{n}", "dem": epoch_result("dense", "dsm.tif", n), "nodata": None,
             "correlation": epoch_result("dense", "correlation.tif", n),
             "accuracy": {"checkpoints": epoch_result("inputs", "checkpoints.csv", n)}}
            for n in SURVEY_EPOCHS
        ]
        if CHANGE["masks"] is None:
            CHANGE["masks"] = []
            if "gully" in config:
                CHANGE["masks"].append({"name": "gully", "file": result("gully", "gully_polygons.gpkg"), "kind": "vector",
                                        "by": "gully_id", "unstable": True})
            if "obia" in config and config["obia"]["kite_scale"]["enabled"]:
                CHANGE["masks"].append({"name": "bare_soil", "file": result("obia", "kite/bare_soil.gpkg"), "kind": "vector",
                                        "by": None, "unstable": True})
        if CHANGE["heads_file"] is None:
            CHANGE["heads_file"] = result("twin", "observed/gully_heads.gpkg")
        if CHANGE.get("sections_file") is None and "polygons" in config:
            CHANGE["sections_file"] = result("polygons", "cross_sections.gpkg")
        if CHANGE["evaluation"]:
            _twin_truth = {"dem1_truth": epoch_result("twin", "truth/dsm.tif", 1), "dem2_truth": epoch_result("twin", "truth/dsm.tif", 2),
                           "heads1_truth": epoch_result("twin", "truth/gully_heads.gpkg", 1),
                           "heads2_truth": epoch_result("twin", "truth/gully_heads.gpkg", 2),
                           "polygons1_truth": epoch_result("twin", "truth/gully_polygons.gpkg", 1),
                           "polygons2_truth": epoch_result("twin", "truth/gully_polygons.gpkg", 2)}
            CHANGE["evaluation"] = {"polygons1_truth": None, "polygons2_truth": None, **CHANGE["evaluation"]}
            CHANGE["evaluation"] = {k: (_twin_truth[k] if v is None and k in _twin_truth else v) for k, v in CHANGE["evaluation"].items()}
    else:
        if CHANGE["masks"] is None:
            CHANGE["masks"] = []
        _missing_truth = [k for k in ("dem1_truth", "dem2_truth") if CHANGE["evaluation"] and CHANGE["evaluation"][k] is None]
        if _missing_truth:
            raise WorkflowError(f"Invalid configuration: change.evaluation.{_missing_truth[0]}: null means the twin's own "
                                "truth, which only a twin with change.epochs null has; name the GeoTIFF")
    from kitegully.change.params import OUTPUT_FILES as CHANGE_OUTPUT_FILES, THRESHOLD_METHODS as CHANGE_METHODS
    CHANGE_CAT = "Change between epochs"

    CHANGE_METHOD_KEYS = ("coregistration", "thresholds", "budget", "headcuts", "quality", "widening")
    CHANGE_PARAMS_METHODS = {k: CHANGE[k] for k in CHANGE_METHOD_KEYS if k in CHANGE}
    # issue 21: sites with a tiling section run the per-cell work as tile jobs of the common grid
    # (kitegully.change.tiles): change_plan, change_stable_tile per tile, change_coregister (one
    # global fit on the untiled sample), change_tile per tile (DoD, sigma, thresholds with the
    # coherence window's halo, partial budget sums) and change_merge (rasters, budgets from the
    # sums, variogram, headcuts, widening, figures); the products equal change_detect's.
    CHANGE_TILED = "tiling" in config

    def change_epoch_inputs(wildcards=None):
        files = {f"dem{i + 1}": e["dem"] for i, e in enumerate(CHANGE["epochs"])}
        for i, e in enumerate(CHANGE["epochs"]):
            for k in ("error_raster", "checkpoints"):
                if e["accuracy"].get(k):
                    files[f"{k}{i + 1}"] = e["accuracy"][k]
            if e.get("correlation"):
                files[f"correlation{i + 1}"] = e["correlation"]
        return files

    def change_mask_inputs(wildcards=None):
        return {f"mask_{m['name']}": m["file"] for m in CHANGE["masks"]}

    def change_feature_inputs(wildcards=None):
        files = {}
        if CHANGE["heads_file"]:
            files["heads"] = CHANGE["heads_file"]
        if CHANGE.get("sections_file"):
            files["sections"] = CHANGE["sections_file"]
        return files

    def change_inputs(wildcards=None):
        return {**change_epoch_inputs(), **change_mask_inputs(), **change_feature_inputs()}

    # The products' file names are the library's (kitegully.change.params.OUTPUT_FILES); these are shown in the report.
    CHANGE_CAPTIONS = {"coregistration": "change_coregistration", "sigma": "change_sigma", "budget": "change_budget",
                       "dod_map": "change_dod_map", "budget_bars": "change_budget_bars", "histogram": "change_histogram",
                       "variogram_png": "change_variogram"}

    def change_outputs():
        return {key: report(result("change", name), caption=caption(CHANGE_CAPTIONS[key]), category=CHANGE_CAT)
                if key in CHANGE_CAPTIONS else result("change", name) for key, name in CHANGE_OUTPUT_FILES.items()}

    if CHANGE_TILED:
        from kitegully.terrain.tiling import TilingParams as _ChangeTilingParams

        _CHANGE_TILING = _ChangeTilingParams.from_config(config)
        CHANGE_TILE_NAMES = _CHANGE_TILING.names()
        CHANGE_TILING_PARAMS = {"tile_m": _CHANGE_TILING.tile_m, "width_m": _CHANGE_TILING.width_m,
                                "height_m": _CHANGE_TILING.height_m}

        wildcard_constraints:
            tile=r"r\d{3}_c\d{3}",

        rule change_plan:
            """Whole-grid numbers of the tiled change stage: epoch-1 maximum, each epoch's sigma (issue 21)."""
            input:
                unpack(change_epoch_inputs),
            output:
                plan=result("change", "tiles/plan.json"),
            params:
                epochs=CHANGE["epochs"],
                crs=config["site"]["crs"],
                methods=CHANGE_PARAMS_METHODS,
            log:
                logfile("change", "plan"),
            benchmark:
                benchfile("change", "plan")
            script:
                "../scripts/change_plan.py"

        rule change_stable_tile:
            """Stable ground, co-registration candidates and dh before co-registration of one tile (issue 21)."""
            input:
                unpack(change_epoch_inputs),
                unpack(change_mask_inputs),
                plan=result("change", "tiles/plan.json"),
            output:
                tile=temp(result("change", "tiles/{tile}.stable.npz")),
            params:
                epochs=CHANGE["epochs"],
                masks=CHANGE["masks"],
                methods=CHANGE_PARAMS_METHODS,
                seed=config["seed"],
                crs=config["site"]["crs"],
                tiling=CHANGE_TILING_PARAMS,
            log:
                logfile("change", "stable_tile_{tile}"),
            benchmark:
                benchfile("change", "stable_tile_{tile}")
            script:
                "../scripts/change_stable_tile.py"

        rule change_coregister:
            """The global co-registration fit on the stable cells of all tiles (issue 21)."""
            input:
                unpack(change_epoch_inputs),
                tiles=expand(result("change", "tiles/{tile}.stable.npz"), tile=CHANGE_TILE_NAMES),
            output:
                coreg=result("change", "tiles/coregistration.json"),
            params:
                epochs=CHANGE["epochs"],
                methods=CHANGE_PARAMS_METHODS,
                seed=config["seed"],
                crs=config["site"]["crs"],
            log:
                logfile("change", "coregister"),
            benchmark:
                benchfile("change", "coregister")
            script:
                "../scripts/change_coregister.py"

        rule change_tile:
            """DoD, sigma, thresholds and partial budget sums of one tile (issue 21)."""
            input:
                unpack(change_epoch_inputs),
                unpack(change_mask_inputs),
                plan=result("change", "tiles/plan.json"),
                coreg=result("change", "tiles/coregistration.json"),
                stable=result("change", "tiles/{tile}.stable.npz"),
            output:
                tile=temp(result("change", "tiles/{tile}.change.npz")),
            params:
                epochs=CHANGE["epochs"],
                masks=CHANGE["masks"],
                methods=CHANGE_PARAMS_METHODS,
                seed=config["seed"],
                crs=config["site"]["crs"],
                tiling=CHANGE_TILING_PARAMS,
            log:
                logfile("change", "tile_{tile}"),
            benchmark:
                benchfile("change", "tile_{tile}")
            script:
                "../scripts/change_tile.py"

        rule change_merge:
            """The change products from the tiles: rasters, budgets from the tiles' sums, tables and figures (issue 21)."""
            input:
                unpack(change_feature_inputs),
                dem1=CHANGE["epochs"][0]["dem"],
                dem2=CHANGE["epochs"][1]["dem"],
                tiles=expand(result("change", "tiles/{tile}.change.npz"), tile=CHANGE_TILE_NAMES),
                plan=result("change", "tiles/plan.json"),
                coreg=result("change", "tiles/coregistration.json"),
            output:
                **change_outputs(),
            params:
                epochs=CHANGE["epochs"],
                heads_file=CHANGE["heads_file"],
                sections_file=CHANGE.get("sections_file"),
                methods=CHANGE_PARAMS_METHODS,
                figure=CHANGE["figure"],
                seed=config["seed"],
                crs=config["site"]["crs"],
                attribution=config["site"].get("attribution"),
            log:
                logfile("change", "merge"),
            benchmark:
                benchfile("change", "merge")
            script:
                "../scripts/change_merge.py"

        CHANGE_OUT = rules.change_merge.output

    else:

        rule change_detect:
            """Co-registration, DoD, sigma, thresholds, budgets, headcuts and figures."""
            input:
                unpack(change_inputs),
            output:
                **change_outputs(),
            params:
                epochs=CHANGE["epochs"],
                masks=CHANGE["masks"],
                heads_file=CHANGE["heads_file"],
                sections_file=CHANGE.get("sections_file"),
                methods=CHANGE_PARAMS_METHODS,
                figure=CHANGE["figure"],
                seed=config["seed"],
                crs=config["site"]["crs"],
                attribution=config["site"].get("attribution"),
            log:
                logfile("change", "detect"),
            benchmark:
                benchfile("change", "detect")
            threads: 1
            script:
                "../scripts/change_detect.py"

        CHANGE_OUT = rules.change_detect.output

    add_targets(CHANGE_OUT.budget, CHANGE_OUT.dod_map)

    if CHANGE["evaluation"]:

        CHANGE_EVAL = CHANGE["evaluation"]

        rule change_evaluate:
            """Evaluation only: reads the known change (truth surfaces and heads)."""
            input:
                dod=CHANGE_OUT.dod,
                sigma_dod=CHANGE_OUT.sigma_dod,
                budget=CHANGE_OUT.budget,
                headcuts=CHANGE_OUT.headcuts,
                widening=CHANGE_OUT.widening,
                **({"sections": CHANGE["sections_file"]} if CHANGE.get("sections_file") else {}),
                **{f"thresholded_{m}": getattr(CHANGE_OUT, f"thresholded_{m}") for m in CHANGE_METHODS},
                truth1=CHANGE_EVAL["dem1_truth"],
                truth2=CHANGE_EVAL["dem2_truth"],
                **{k: CHANGE_EVAL[k] for k in ("heads1_truth", "heads2_truth", "polygons1_truth", "polygons2_truth") if CHANGE_EVAL.get(k)},
                **change_mask_inputs(),
                **({"heads": CHANGE["heads_file"]} if CHANGE["heads_file"] else {}),
            output:
                detection=report(result("change", "detection.csv"), caption=caption("change_detection"), category=CHANGE_CAT),
                budget_vs_truth=report(result("change", "budget_vs_truth.csv"), caption=caption("change_budget_vs_truth"), category=CHANGE_CAT),
                headcuts_vs_truth=report(result("change", "headcut_retreat_vs_truth.csv"), caption=caption("change_headcuts"), category=CHANGE_CAT),
                moritani_plots=result("change", "moritani_plots.csv"),
                widening_vs_truth=result("change", "widening_vs_truth.csv"),
                headcuts_on_truth=result("change", "headcut_retreat_on_true_surfaces.csv"),
                summary=report(result("change", "evaluation_summary.csv"), caption=caption("change_evaluation"), category=CHANGE_CAT),
            params:
                masks=CHANGE["masks"],
                evaluation={k: CHANGE_EVAL[k] for k in ("plot_m", "min_lowering_m", "head_match_m", "net_tolerance")},
                widening_margin_m=(CHANGE.get("widening") or {}).get("margin_m", 3.0),
                methods=CHANGE_PARAMS_METHODS,
                seed=config["seed"],
            log:
                logfile("change", "evaluate"),
            script:
                "../scripts/change_evaluate.py"

        add_targets(rules.change_evaluate.output.summary)
