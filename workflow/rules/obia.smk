# Stage obia: bare-soil (eroded area) classification with ExG and OBIA (Mayr et al. 2016).
#
# Close-range scene study (twin sites): synthetic 2 cm orthophoto + DEM scenes ->
# segmentation + automatic ExG threshold -> per-scene accuracy and figures -> tables.
# Kite-scale application: bare-soil map of the site's dense orthophoto; only built when
# obia.kite_scale.enabled is true (needs the dense stage's orthophoto.tif and dsm.tif).

from kitegully.obia.stage import METHOD_KEYS as _OBIA_METHOD_KEYS
from kitegully.twin.closerange import scene_names as _obia_scene_names

if "obia" in config:

    OBIA = config["obia"]
    OBIA_SCENES = _obia_scene_names(len(OBIA["scenes"]["list"])) if IS_TWIN else []
    # the method sub-sections only (ObiaParams.from_config): a change to obia.scenes or
    # obia.kite_scale does not rerun the classification of the other products
    OBIA_METHOD = {k: OBIA[k] for k in _OBIA_METHOD_KEYS}


    def _obia_scene(name):
        return result("obia", "scenes/{scene}/" + name)


    wildcard_constraints:
        scene="scene_[0-9]+",


    rule obia_scene:
        """Synthetic close-range scene: orthophoto, DEM, surveyed markers and truth masks."""
        output:
            orthophoto=_obia_scene("orthophoto.tif"),
            dem=_obia_scene("dem.tif"),
            markers=_obia_scene("markers.csv"),
            truth_eroded=_obia_scene("truth/eroded.tif"),
            truth_markers=_obia_scene("truth/markers.tif"),
            truth_meta=_obia_scene("truth/scene.json"),
        params:
            scenes=OBIA["scenes"],
            seed=config["seed"],
            crs=config["site"]["crs"],
        log:
            logfile("obia", "generate_{scene}"),
        benchmark:
            benchfile("obia", "generate_{scene}")
        threads: 1
        script:
            "../scripts/obia_scene.py"


    rule obia_classify:
        """Seeded region growing on R, G, B, slope; ExG valley threshold; grass / eroded."""
        input:
            orthophoto=_obia_scene("orthophoto.tif"),
            dem=_obia_scene("dem.tif"),
            markers=_obia_scene("markers.csv"),
        output:
            segments=_obia_scene("segments.tif"),
            exg=_obia_scene("exg_blurred.tif"),
            classification=_obia_scene("classification.tif"),
            classification_otsu=_obia_scene("classification_otsu.tif"),
            polygons=_obia_scene("eroded_areas.gpkg"),
            histogram=_obia_scene("exg_histogram.csv"),
            info=_obia_scene("threshold.json"),
        params:
            obia=OBIA_METHOD,
        log:
            logfile("obia", "classify_{scene}"),
        benchmark:
            benchfile("obia", "classify_{scene}")
        threads: 1
        script:
            "../scripts/obia_classify.py"


    rule obia_evaluate:
        """Confusion matrices against the truth mask and the per-scene figure (001 Figs 3-4)."""
        input:
            orthophoto=_obia_scene("orthophoto.tif"),
            segments=_obia_scene("segments.tif"),
            classification=_obia_scene("classification.tif"),
            classification_otsu=_obia_scene("classification_otsu.tif"),
            histogram=_obia_scene("exg_histogram.csv"),
            info=_obia_scene("threshold.json"),
            truth_eroded=_obia_scene("truth/eroded.tif"),
        output:
            confusion=_obia_scene("confusion.json"),
            figure=report(
                _obia_scene("scene_figure.png"),
                caption=caption("obia_scene"),
                category="Bare soil (OBIA)",
                subcategory="Close-range scenes",
                labels={"scene": "{scene}"},
            ),
        log:
            logfile("obia", "evaluate_{scene}"),
        script:
            "../scripts/obia_evaluate.py"


    rule obia_summary:
        """Accuracy (001 Table 3), eroded areas (001 Table 2), valley vs Otsu over all scenes."""
        input:
            confusion=expand(_obia_scene("confusion.json"), scene=OBIA_SCENES),
        output:
            accuracy=report(result("obia", "accuracy.csv"), caption=caption("obia_accuracy"), category="Bare soil (OBIA)", subcategory="Tables"),
            accuracy_md=result("obia", "accuracy.md"),
            areas=report(result("obia", "eroded_areas.csv"), caption=caption("obia_eroded_areas"), category="Bare soil (OBIA)", subcategory="Tables"),
            areas_md=result("obia", "eroded_areas.md"),
            comparison=report(result("obia", "valley_vs_otsu.csv"), caption=caption("obia_valley_vs_otsu"), category="Bare soil (OBIA)", subcategory="Tables"),
            comparison_md=result("obia", "valley_vs_otsu.md"),
            figure=report(result("obia", "accuracy_summary.png"), caption=caption("obia_summary"), category="Bare soil (OBIA)", subcategory="Tables"),
        log:
            logfile("obia", "summary"),
        script:
            "../scripts/obia_summary.py"


    # issue 21: sites with a tiling section map the kite orthophoto as tile jobs of whole blocks
    # of obia.kite_scale.tile_cells (kitegully.obia.kite_tiles): obia_kite_histogram per tile,
    # obia_kite_tile per tile (the global threshold from all tiles' histograms), obia_kite_merge;
    # the merged map equals the untiled obia_kite_scale cell for cell. Other sites keep one job.
    OBIA_KITE_TILED = "tiling" in config and OBIA["kite_scale"]["enabled"]

    if OBIA_KITE_TILED:
        from kitegully.terrain.tiling import TilingParams as _KiteTilingParams

        _KITE_TILING = _KiteTilingParams.from_config(config)
        KITE_TILE_NAMES = _KITE_TILING.names()
        KITE_TILING_PARAMS = {"tile_m": _KITE_TILING.tile_m, "width_m": _KITE_TILING.width_m,
                              "height_m": _KITE_TILING.height_m}

        wildcard_constraints:
            tile=r"r\d{3}_c\d{3}",

        rule obia_kite_histogram:
            """Fine histogram of the blurred index over one tile's blocks (issue 21)."""
            input:
                orthophoto=result("dense", "orthophoto.tif"),
                dsm=result("dense", "dsm.tif"),
            output:
                hist=temp(result("obia", "kite/tiles/{tile}.hist.npz")),
            params:
                obia=OBIA_METHOD,
                tile_cells=OBIA["kite_scale"]["tile_cells"],
                tiling=KITE_TILING_PARAMS,
            log:
                logfile("obia", "kite_histogram_{tile}"),
            benchmark:
                benchfile("obia", "kite_histogram_{tile}")
            script:
                "../scripts/obia_kite_histogram.py"

        rule obia_kite_tile:
            """Segment and classify one tile's blocks with the global threshold (issue 21)."""
            input:
                orthophoto=result("dense", "orthophoto.tif"),
                dsm=result("dense", "dsm.tif"),
                hists=expand(result("obia", "kite/tiles/{tile}.hist.npz"), tile=KITE_TILE_NAMES),
            output:
                tile=temp(result("obia", "kite/tiles/{tile}.classes.npz")),
            params:
                obia=OBIA_METHOD,
                tile_cells=OBIA["kite_scale"]["tile_cells"],
                tiling=KITE_TILING_PARAMS,
            log:
                logfile("obia", "kite_tile_{tile}"),
            benchmark:
                benchfile("obia", "kite_tile_{tile}")
            script:
                "../scripts/obia_kite_tile.py"

        rule obia_kite_merge:
            """The tiles' classes into the bare-soil map, its polygons, threshold record and figure (issue 21)."""
            input:
                tiles=expand(result("obia", "kite/tiles/{tile}.classes.npz"), tile=KITE_TILE_NAMES),
                hists=expand(result("obia", "kite/tiles/{tile}.hist.npz"), tile=KITE_TILE_NAMES),
                orthophoto=result("dense", "orthophoto.tif"),
            output:
                bare_soil=result("obia", "kite/bare_soil.tif"),
                polygons=result("obia", "kite/bare_soil.gpkg"),
                info=result("obia", "kite/threshold.json"),
                figure=report(result("obia", "kite/bare_soil_map.png"), caption=caption("obia_kite_map"), category="Bare soil (OBIA)", subcategory="Kite scale"),
            params:
                obia=OBIA_METHOD,
                figure_max_px=OBIA["kite_scale"]["figure_max_px"],
                attribution=config["site"].get("attribution"),
            log:
                logfile("obia", "kite_merge"),
            benchmark:
                benchfile("obia", "kite_merge")
            script:
                "../scripts/obia_kite_merge.py"

    if not OBIA_KITE_TILED:

        rule obia_kite_scale:
            """Bare-soil map of the site's kite orthophoto (tiled OBIA with a global threshold)."""
            input:
                orthophoto=result("dense", "orthophoto.tif"),
                dsm=result("dense", "dsm.tif"),
            output:
                bare_soil=result("obia", "kite/bare_soil.tif"),
                polygons=result("obia", "kite/bare_soil.gpkg"),
                info=result("obia", "kite/threshold.json"),
                figure=report(result("obia", "kite/bare_soil_map.png"), caption=caption("obia_kite_map"), category="Bare soil (OBIA)", subcategory="Kite scale"),
            params:
                obia=OBIA_METHOD,
                tile_cells=OBIA["kite_scale"]["tile_cells"],
                figure_max_px=OBIA["kite_scale"]["figure_max_px"],
                attribution=config["site"].get("attribution"),
            log:
                logfile("obia", "kite_scale"),
            benchmark:
                benchfile("obia", "kite_scale")
            threads: 1
            script:
                "../scripts/obia_kite_scale.py"


    rule obia_kite_accuracy:
        """Kite-scale bare-soil map against the twin's land-cover truth (twin sites only)."""
        input:
            bare_soil=result("obia", "kite/bare_soil.tif"),
            landcover=result("twin", "truth/landcover.tif"),
            landcover_classes=result("twin", "truth/landcover_classes.csv"),
        output:
            accuracy=report(result("obia", "kite/accuracy.csv"), caption=caption("obia_kite_accuracy"), category="Bare soil (OBIA)", subcategory="Kite scale"),
            areas=result("obia", "kite/bare_areas.csv"),
            per_class=report(result("obia", "kite/landcover_agreement.csv"), caption=caption("obia_kite_landcover"), category="Bare soil (OBIA)", subcategory="Kite scale"),
        params:
            bare_classes=OBIA["kite_scale"]["bare_landcover_classes"],
            excluded_classes=OBIA["kite_scale"]["excluded_landcover_classes"],
            site=SITE,
        log:
            logfile("obia", "kite_accuracy"),
        script:
            "../scripts/obia_kite_accuracy.py"


    if IS_TWIN and OBIA_SCENES:
        add_targets(
            result("obia", "accuracy.csv"),
            result("obia", "eroded_areas.csv"),
            result("obia", "valley_vs_otsu.csv"),
            result("obia", "accuracy_summary.png"),
            *expand(_obia_scene("scene_figure.png"), scene=OBIA_SCENES),
        )
    if OBIA["kite_scale"]["enabled"] and "dense" not in config:
        raise WorkflowError("Invalid configuration: obia.kite_scale.enabled needs the dense stage (section 'dense') for orthophoto.tif and dsm.tif")
    if OBIA["kite_scale"]["enabled"]:
        add_targets(result("obia", "kite/bare_soil.tif"), result("obia", "kite/bare_soil.gpkg"), result("obia", "kite/bare_soil_map.png"))
        if IS_TWIN:
            add_targets(result("obia", "kite/accuracy.csv"))
