# Gully network mapping and its validation (Feurer et al. 2018 sect. 2.5-2.6.2, Figs 3, 4, 9b;
# METHODS.md 1.5-1.6). Library: kitegully.terrain, kitegully.gully (validation.score_network: the scoring protocol), kitegully.evaluate.network.

from kitegully.gully.pipeline import GullyParams as _GullyParams

if "gully" in config:

    GULLY = config["gully"]
    # Each rule gets only the keys it reads (the params rerun trigger): the mapping keys are
    # exactly the fields of GullyParams, so a change to gully.validation.* or
    # gully.sensitivity.* does not rerun gully_map.
    GULLY_MAPPING = {k: GULLY[k] for k in _GullyParams.__dataclass_fields__ if k in GULLY}  # optional keys keep their defaults
    GULLY_CAT = "Gully network"
    GULLY_ATTRIBUTION = config["site"].get("attribution")
    if GULLY["dem"] == "truth_plus_noise" and not IS_TWIN:
        raise WorkflowError("Invalid configuration: gully.dem: truth_plus_noise needs a twin site; use dense")
    if GULLY["heads_file"] is None and not IS_TWIN and GULLY["heads"] != "automatic":
        raise WorkflowError("Invalid configuration: gully.heads_file: a real site must name its gully head file")

    if GULLY["dem"] == "file" and not GULLY.get("dem_file"):
        raise WorkflowError("Invalid configuration: gully.dem: file needs gully.dem_file (a DEM GeoTIFF in the site CRS)")
    if GULLY.get("dem_file") and GULLY["dem"] != "file":
        raise WorkflowError(f"Invalid configuration: gully.dem_file is given but gully.dem is {GULLY['dem']}; set gully.dem: file to map on it")

    def mapping_dem(wildcards=None):
        """The DEM the gullies are mapped on, chosen by gully.dem."""
        if GULLY["dem"] == "dense":
            return result("dense", "dsm.tif")
        if GULLY["dem"] == "file":  # a DEM the site hands in (LiDAR, TLS, another software's DSM), checked
            return checked_dem("gully")
        # gully.dem: truth_plus_noise, an evaluation stand-in (twins only): NOT photogrammetric.
        return result("gully", "standin_dem_truth_plus_noise.tif")

    GULLY_HEADS = GULLY["heads_file"] or result("twin", "observed/gully_heads.gpkg")
    # gully.heads: automatic needs no head file
    GULLY_HEADS_INPUT = {} if GULLY["heads"] == "automatic" else {"heads": GULLY_HEADS}
    # automatic heads (and head_snap: incision, which uses their incision map) with dsm_sigma_z_m: null
    # measure the DSM noise at the (observed) checkpoints
    GULLY_CROWNS = bool(GULLY.get("crowns", {}).get("enabled", False))  # gully.crowns: the orthophoto's crowns
    # crowns and trace_ground stand on the incision map's ground surface: they need its parameters whatever the heads
    GULLY_GROUND_SURFACE = GULLY_CROWNS or bool(GULLY.get("trace_ground", False))
    if GULLY_CROWNS:
        if GULLY["dem"] != "dense":
            raise WorkflowError("Invalid configuration: gully.crowns needs gully.dem: dense (the orthophoto of that DSM)")
        GULLY_HEADS_INPUT["ortho"] = result("dense", "orthophoto.tif")
    if (GULLY["heads"] != "digitised" or GULLY["head_snap"] in ("incision", "relief", "posterior") or GULLY_GROUND_SURFACE) and GULLY["automatic_heads"]["dsm_sigma_z_m"] is None:
        _cps = result("twin", "observed/checkpoints.csv") if IS_TWIN else config.get("inputs", {}).get("checkpoints")
        if not _cps:
            raise WorkflowError("Invalid configuration: gully.automatic_heads.dsm_sigma_z_m: null needs checkpoints (inputs.checkpoints)")
        GULLY_HEADS_INPUT["checkpoints"] = _cps
    GULLY_REFERENCE = GULLY["reference_network_file"] or (
        result("twin", "observed/field_network.gpkg") if IS_TWIN else None
    )
    GULLY_CATCHMENT = GULLY["validation"]["catchment_file"]
    GULLY_TRUTH = {"truth": result("twin", "truth/gully_polygons.gpkg")} if IS_TWIN else {}

    if GULLY["dem"] == "truth_plus_noise":

        rule gully_standin_dem:
            input:
                dtm=result("twin", "truth/dtm.tif"),
            output:
                dem=result("gully", "standin_dem_truth_plus_noise.tif"),
            params:
                noise=GULLY["standin"],
                seed=config["seed"],
            log:
                logfile("gully", "standin_dem"),
            benchmark:
                benchfile("gully", "standin_dem")
            script:
                "../scripts/gully_standin_dem.py"

    # Large sites (config section tiling, issue 21): the depth map and the depression fill of
    # the tracing surface run as tile jobs (the tiled Priority-Flood, Barnes 2016, equals the
    # untiled fill bit for bit; depth tiles read the kernel radius around them) and gully_map
    # reads the merged products. Other sites do both inside gully_map, unchanged.
    GULLY_TILED = "tiling" in config
    GULLY_FILLED_INPUT = {
        "trace_surface": result("gully", "tiles/trace_surface.tif"),  # what the fill was made from: not made again
        "filled": result("gully", "tiles/filled_trace_surface.tif"),
        "smoothed": result("gully", "tiles/smoothed_dem.tif"),
        "depth": result("gully", "tiles/depth.tif"),
    } if GULLY_TILED else {}
    # gully.crowns on a tiled site: the trace-surface job makes the crown mask on the whole grid (the
    # fill tiles read the surface interpolated under it) and gully_map bridges with the same mask
    GULLY_CROWN_MASK = {"crowns": result("gully", "tiles/crown_mask.tif")} if GULLY_TILED and GULLY_CROWNS else {}
    GULLY_FILLED_INPUT.update(GULLY_CROWN_MASK)

    # gully.heads: both also writes the network of the digitised heads alone (the paper's procedure on
    # the same DEM), and gully_validate scores it beside the combined one (Table 4 for both)
    GULLY_BOTH = GULLY["heads"] == "both"
    GULLY_DIGITISED_OUT = {"mapped_network_digitised": result("gully", "gully_network_mapped_digitised.gpkg")} if GULLY_BOTH else {}

    rule gully_map:
        input:
            unpack(lambda wc: GULLY_HEADS_INPUT),
            unpack(lambda wc: GULLY_FILLED_INPUT),
            dem=mapping_dem(),
        output:
            depth=result("gully", "depth.tif"),
            smoothed=result("gully", "smoothed_dem.tif"),
            gully_map=result("gully", "gully_map.tif"),
            gully_map_whole=result("gully", "gully_map_whole_patches.tif"),
            network=result("gully", "gully_network.gpkg"),
            mapped_network=result("gully", "gully_network_mapped.gpkg"),
            network_cells=result("gully", "gully_network_cells.npz"),
            polygons=result("gully", "gully_polygons.gpkg"),
            patches=result("gully", "depth_patches.csv"),
            summary=report(result("gully", "gully_summary.csv"), caption=caption("gully_summary"), category=GULLY_CAT),
            **GULLY_DIGITISED_OUT,
        params:
            mapping=GULLY_MAPPING,
            heads=GULLY["heads"],
            automatic_heads=GULLY["automatic_heads"],
            dem_source=GULLY["dem_file"] if GULLY["dem"] == "file" else GULLY["dem"],
            crs=config["site"]["crs"],
        threads: GULLY["threads"]
        log:
            logfile("gully", "map"),
        benchmark:
            benchfile("gully", "map")
        script:
            "../scripts/gully_map.py"

    rule gully_section:
        input:
            dem=mapping_dem(),
            smoothed=rules.gully_map.output.smoothed,
            depth=rules.gully_map.output.depth,
            gully_map=rules.gully_map.output.gully_map,
            network_cells=rules.gully_map.output.network_cells,
        output:
            figure=report(result("gully", "gully_section.png"), caption=caption("gully_section"), category=GULLY_CAT),
        params:
            half_length_m=GULLY["section_half_length_m"],
            sigma_m=GULLY["sigma_m"],
            depth_threshold_m=GULLY["depth_threshold_m"],
            attribution=GULLY_ATTRIBUTION,
        log:
            logfile("gully", "section"),
        script:
            "../scripts/gully_section.py"

    GULLY_TARGETS = [rules.gully_map.output.summary, rules.gully_section.output.figure]

    if GULLY_REFERENCE:

        rule gully_validate:
            input:
                unpack(lambda wc: {"catchment": GULLY_CATCHMENT} if GULLY_CATCHMENT else {}),
                **GULLY_DIGITISED_OUT,
                dem=mapping_dem(),
                gully_map=rules.gully_map.output.gully_map,
                mapped_network=rules.gully_map.output.mapped_network,
                reference=GULLY_REFERENCE,
            output:
                table=report(
                    result("gully", "network_validation.csv"), caption=caption("gully_network_validation"), category=GULLY_CAT
                ),
                tolerances=report(
                    result("gully", "network_validation_tolerances.csv"),
                    caption=caption("gully_network_validation_tolerances"),
                    category=GULLY_CAT,
                ),
                figure=report(
                    result("gully", "gully_validation_map.png"), caption=caption("gully_validation_map"), category=GULLY_CAT
                ),
                **({"table_digitised": report(result("gully", "network_validation_digitised.csv"),
                                              caption=caption("gully_network_validation_digitised"), category=GULLY_CAT),
                    "tolerances_digitised": result("gully", "network_validation_tolerances_digitised.csv")}
                   if GULLY_BOTH else {}),
            params:
                validation={k: v for k, v in GULLY["validation"].items() if k != "catchment_file"},
                crs=config["site"]["crs"],
                attribution=GULLY_ATTRIBUTION,
            threads: GULLY["threads"] if GULLY_BOTH else 1  # gully.heads: both scores the two networks side by side
            log:
                logfile("gully", "validate"),
            benchmark:
                benchfile("gully", "validate")
            script:
                "../scripts/gully_validate.py"

        GULLY_TARGETS += [rules.gully_validate.output.table, rules.gully_validate.output.figure]

    if IS_TWIN:

        # Evaluation rule: the only gully rule besides the sensitivity table that reads truth/.
        rule gully_area_scores:
            input:
                gully_map=rules.gully_map.output.gully_map,
                gully_map_whole=rules.gully_map.output.gully_map_whole,
                truth=result("twin", "truth/gully_polygons.gpkg"),
            output:
                table=report(result("gully", "gully_area_scores.csv"), caption=caption("gully_area_scores"), category=GULLY_CAT),
            params:
                crs=config["site"]["crs"],
            log:
                logfile("gully", "area_scores"),
            script:
                "../scripts/gully_area_scores.py"

        GULLY_TARGETS.append(rules.gully_area_scores.output.table)

    rule gully_sensitivity:
        input:
            unpack(lambda wc: {**({"reference": GULLY_REFERENCE} if GULLY_REFERENCE else {}), **GULLY_TRUTH}),
            dem=mapping_dem(),
            depth=rules.gully_map.output.depth,
            network_cells=rules.gully_map.output.network_cells,
        output:
            table=report(result("gully", "gully_sensitivity.csv"), caption=caption("gully_sensitivity"), category=GULLY_CAT),
        params:
            sensitivity=GULLY["sensitivity"],
            mapping=GULLY_MAPPING,
            tolerance_m=GULLY["validation"]["tolerance_m"],
            crs=config["site"]["crs"],
        threads: GULLY["threads"]
        log:
            logfile("gully", "sensitivity"),
        benchmark:
            benchfile("gully", "sensitivity")
        script:
            "../scripts/gully_sensitivity.py"

    GULLY_TARGETS.append(rules.gully_sensitivity.output.table)
    add_targets(*GULLY_TARGETS)

    if GULLY_TILED:
        from kitegully.terrain.tiling import TilingParams as _TilingParams

        _GULLY_TILING = _TilingParams.from_config(config)
        # the tile names follow from the config alone (site extent, tiling.tile_m): no checkpoint
        GULLY_TILE_NAMES = _GULLY_TILING.names()
        GULLY_TILING_PARAMS = {"tile_m": _GULLY_TILING.tile_m, "width_m": _GULLY_TILING.width_m,
                               "height_m": _GULLY_TILING.height_m}

        wildcard_constraints:
            tile=r"r\d{3}_c\d{3}",

        rule gully_depth_tile:
            input:
                dem=mapping_dem(),
            output:
                tile=temp(result("gully", "tiles/depth/{tile}.npz")),
            params:
                sigma_m=GULLY["sigma_m"],
                truncate_sigmas=GULLY["truncate_sigmas"],
                tiling=GULLY_TILING_PARAMS,
            log:
                logfile("gully", "depth_tile_{tile}"),
            benchmark:
                benchfile("gully", "depth_tile_{tile}")
            script:
                "../scripts/gully_depth_tile.py"

        rule gully_depth_mosaic:
            input:
                dem=mapping_dem(),
                tiles=expand(result("gully", "tiles/depth/{tile}.npz"), tile=GULLY_TILE_NAMES),
            output:
                smoothed=result("gully", "tiles/smoothed_dem.tif"),
                depth=result("gully", "tiles/depth.tif"),
            params:
                tiling=GULLY_TILING_PARAMS,
            log:
                logfile("gully", "depth_mosaic"),
            benchmark:
                benchfile("gully", "depth_mosaic")
            script:
                "../scripts/gully_depth_mosaic.py"

        rule gully_trace_surface:
            input:
                unpack(lambda wc: {k: v for k, v in GULLY_HEADS_INPUT.items()
                                   if (k == "ortho" and GULLY_CROWNS) or (k == "checkpoints" and GULLY_GROUND_SURFACE)}),
                dem=mapping_dem(),
            output:
                surface=result("gully", "tiles/trace_surface.tif"),
                **GULLY_CROWN_MASK,
            params:
                mapping=GULLY_MAPPING,
                # the incision map's settings (crown mask, trace_ground): where unused they must not trigger a rerun
                **({"heads": GULLY["heads"], "automatic_heads": GULLY["automatic_heads"]} if GULLY_GROUND_SURFACE else {}),
                crs=config["site"]["crs"],
            threads: GULLY["threads"]
            log:
                logfile("gully", "trace_surface"),
            benchmark:
                benchfile("gully", "trace_surface")
            script:
                "../scripts/gully_trace_surface.py"

        rule gully_fill_tile:
            input:
                surface=rules.gully_trace_surface.output.surface,
            output:
                fill=temp(result("gully", "tiles/fill/{tile}.fill.npz")),
                summary=result("gully", "tiles/fill/{tile}.summary.npz"),
            params:
                tiling=GULLY_TILING_PARAMS,
            log:
                logfile("gully", "fill_tile_{tile}"),
            benchmark:
                benchfile("gully", "fill_tile_{tile}")
            script:
                "../scripts/gully_fill_tile.py"

        rule gully_fill_merge:
            input:
                summaries=expand(result("gully", "tiles/fill/{tile}.summary.npz"), tile=GULLY_TILE_NAMES),
            output:
                spill=result("gully", "tiles/fill/spill.npz"),
            log:
                logfile("gully", "fill_merge"),
            benchmark:
                benchfile("gully", "fill_merge")
            script:
                "../scripts/gully_fill_merge.py"

        rule gully_fill_mosaic:
            input:
                surface=rules.gully_trace_surface.output.surface,
                spill=rules.gully_fill_merge.output.spill,
                fills=expand(result("gully", "tiles/fill/{tile}.fill.npz"), tile=GULLY_TILE_NAMES),
            output:
                filled=result("gully", "tiles/filled_trace_surface.tif"),
            params:
                tiling=GULLY_TILING_PARAMS,
            log:
                logfile("gully", "fill_mosaic"),
            benchmark:
                benchfile("gully", "fill_mosaic")
            script:
                "../scripts/gully_fill_mosaic.py"
