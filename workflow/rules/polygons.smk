# Gully polygons and morphometry (Höfle et al. 2013, Figs 4-12, Table 1; METHODS.md sect. 3).
# Library: kitegully.polygons. Runs on the dense DSM or on a DEM file given in polygons.dem_file.

if "polygons" in config:

    POLY = config["polygons"]
    POLY_CAT = "Gully polygons"
    POLY_ATTRIBUTION = config["site"].get("attribution")
    # null dem_file: the DEM twin's TLS-like DTM on a DEM twin site (issue 16), else the dense DSM
    # a dem_file is read through its checked copy (rule check_dem_file: CRS, grid, nodata)
    POLY_DEM = checked_dem("polygons") if POLY["dem_file"] else (
        result("twin", "observed/dtm.tif") if "dem_twin" in config else result("dense", "dsm.tif"))
    POLY_T = [float(t) for t in POLY["conditioning"]["thresholds_m"]]
    POLY_METHOD = {k: v for k, v in POLY.items() if k not in ("dem_file", "dem_nodata", "evaluation", "figure_max_px")}

    def poly_set(t):
        return result("polygons", f"gully_polygons_t{t:g}.gpkg")

    # Large sites (config section tiling, issue 21): step 6 (medial axes, cross-sections,
    # morphometry; 45 % of the stage at the full Kamech size) runs as one job per tile on the
    # polygons whose centroid the tile holds, then one merge; polygons_map writes the rasters
    # those jobs read in windows. Steps 1-5 stay in polygons_map (measured: README Stage 6b).
    POLY_TILED = "tiling" in config
    POLY_PRODUCTS = {k: result("polygons", f) for k, f in (("axes", "medial_axes.gpkg"), ("sections", "cross_sections.gpkg"),
                                                           ("morphometry", "morphometry.csv"), ("summary", "polygons_summary.csv"))}
    POLY_MORPH_OUT = {
        "axes": POLY_PRODUCTS["axes"],
        "sections": POLY_PRODUCTS["sections"],
        "morphometry": report(POLY_PRODUCTS["morphometry"], caption=caption("polygons_morphometry"), category=POLY_CAT),
        "summary": report(POLY_PRODUCTS["summary"], caption=caption("polygons_summary"), category=POLY_CAT),
    }
    POLY_WINDOWS = {k: result("polygons", f"tiles/{k}.tif") for k in ("labels", "level", "rims")}
    POLY_MAP_OUT = {**POLY_WINDOWS, "summary": result("polygons", "tiles/summary_map.csv")} if POLY_TILED else POLY_MORPH_OUT
    POLY_MORPH_RULE = "polygons_morph_merge" if POLY_TILED else "polygons_map"  # the rule that writes POLY_MORPH_OUT

    rule polygons_map:
        input:
            dem=POLY_DEM,
        output:
            polygons=[poly_set(t) for t in POLY_T],
            dem=result("polygons", "dem.tif"),
            tci=result("polygons", "tci.tif"),
            fill_depth=result("polygons", "fill_depth.tif"),
            breaklines=result("polygons", "breaklines.gpkg"),
            thalweg=result("polygons", "thalweg.gpkg"),
            transects=result("polygons", "transects.gpkg"),
            **POLY_MAP_OUT,
        params:
            cfg=POLY_METHOD,
            crs=config["site"]["crs"],
            morphometry=not POLY_TILED,
        log:
            logfile("polygons", "map"),
        benchmark:
            benchfile("polygons", "map")
        script:
            "../scripts/polygons_map.py"

    rule polygons_figure:
        input:
            dem=rules.polygons_map.output.dem,
            tci=rules.polygons_map.output.tci,
            polygons=rules.polygons_map.output.polygons,
            thalweg=rules.polygons_map.output.thalweg,
            transects=rules.polygons_map.output.transects,
            axes=POLY_PRODUCTS["axes"],
            sections=POLY_PRODUCTS["sections"],
            morphometry=POLY_PRODUCTS["morphometry"],
        output:
            figure=report(result("polygons", "gully_polygons.png"), caption=caption("polygons_map"), category=POLY_CAT),
        params:
            thresholds=POLY_T,
            tci_threshold=POLY["thalweg"]["tci_threshold"],
            max_px=POLY["figure_max_px"],
            attribution=POLY_ATTRIBUTION,
        log:
            logfile("polygons", "figure"),
        script:
            "../scripts/polygons_figure.py"

    POLY_TARGETS = [rules.polygons_map.output, *POLY_PRODUCTS.values(), rules.polygons_figure.output.figure]

    if POLY_TILED:
        from kitegully.terrain.tiling import TilingParams as _PolyTilingParams

        _POLY_TILING = _PolyTilingParams.from_config(config)
        # the tile names follow from the config alone (site extent, tiling.tile_m): no checkpoint
        POLY_TILE_NAMES = _POLY_TILING.names()

        wildcard_constraints:
            tile=r"r\d{3}_c\d{3}",

        rule polygons_morph_tile:
            input:
                **POLY_WINDOWS,
                polygons=poly_set(POLY["morphometry"]["threshold_m"]),
                dem=rules.polygons_map.output.dem,
            output:
                part=temp(result("polygons", "tiles/morph/{tile}.pkl")),
            params:
                cfg=POLY_METHOD,
                tiling={"tile_m": _POLY_TILING.tile_m, "width_m": _POLY_TILING.width_m, "height_m": _POLY_TILING.height_m},
            log:
                logfile("polygons", "morph_tile_{tile}"),
            benchmark:
                benchfile("polygons", "morph_tile_{tile}")
            script:
                "../scripts/polygons_morph_tile.py"

        rule polygons_morph_merge:
            input:
                parts=expand(result("polygons", "tiles/morph/{tile}.pkl"), tile=POLY_TILE_NAMES),
                summary=POLY_MAP_OUT["summary"],
            output:
                **POLY_MORPH_OUT,
            params:
                cfg=POLY_METHOD,
                crs=config["site"]["crs"],
            log:
                logfile("polygons", "morph_merge"),
            benchmark:
                benchfile("polygons", "morph_merge")
            script:
                "../scripts/polygons_morph_merge.py"

    if IS_TWIN:
        # U profile exponent of the true gullies: the photographed twin's or the DEM twin's (issue 16)
        POLY_U_EXPONENT = config["twin"]["gullies"]["u_shape_exponent"] if "twin" in config else config["dem_twin"]["u_shape_exponent"]
        POLY_TRUTH = {"truth": result("twin", "truth/gully_polygons.gpkg"), "centrelines": result("twin", "truth/gully_centrelines.gpkg")}
        if "twin" in config:
            # the photographed twin's land cover: its reservoir hides the gully bed from any survey (observable_region)
            POLY_TRUTH |= {"landcover": result("twin", "truth/landcover.tif"), "classes": result("twin", "truth/landcover_classes.csv")}

        # Evaluation rules: the only polygon rules that read truth/.
        rule polygons_table1:
            input:
                **POLY_TRUTH,
                dem=rules.polygons_map.output.dem,
                polygons=rules.polygons_map.output.polygons,
            output:
                table=report(result("polygons", "table1.csv"), caption=caption("polygons_table1"), category=POLY_CAT),
                comparison=report(result("polygons", "table1_comparison.csv"), caption=caption("polygons_table1_comparison"), category=POLY_CAT),
                manual=result("polygons", "manual_polygons.gpkg"),
                figure=report(result("polygons", "manual_comparison.png"), caption=caption("polygons_manual_comparison"), category=POLY_CAT),
            params:
                operators=POLY["evaluation"]["operators"],
                thresholds=POLY_T,
                auto_threshold=POLY["morphometry"]["threshold_m"],
                u_exponent=POLY_U_EXPONENT,
                seed=config["seed"],
                max_px=POLY["figure_max_px"],
                attribution=POLY_ATTRIBUTION,
            log:
                logfile("polygons", "table1"),
            script:
                "../scripts/polygons_table1.py"

        rule polygons_evaluate:
            input:
                **POLY_TRUTH,
                dem=rules.polygons_map.output.dem,
                polygons=poly_set(POLY["morphometry"]["threshold_m"]),
                sections=POLY_PRODUCTS["sections"],
            output:
                scores=report(result("polygons", "polygon_scores.csv"), caption=caption("polygons_scores"), category=POLY_CAT),
                errors=report(result("polygons", "morphometry_errors.csv"), caption=caption("polygons_morphometry_errors"), category=POLY_CAT),
                sections=result("polygons", "morphometry_errors_sections.csv"),
                volumes=result("polygons", "volume_errors.csv"),
            params:
                cfg={k: v for k, v in POLY["evaluation"].items() if k != "operators"},
                u_exponent=POLY_U_EXPONENT,
            log:
                logfile("polygons", "evaluate"),
            script:
                "../scripts/polygons_evaluate.py"

        POLY_TARGETS += [rules.polygons_table1.output, rules.polygons_evaluate.output]

    if POLY["dem_file"] is None and not Path("workflow/rules/dense.smk").exists():
        logger.warning("polygons stage left out of `all`: no rule file for stage dense yet")
    else:
        add_targets(*POLY_TARGETS)
