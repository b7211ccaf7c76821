# Dense matching (issue 6): object-space multi-view matching of the georeferenced model into
# a DSM, a correlation raster, a true orthophoto and relief shading (MicMac Malt/Tawny-like).

if "dense" in config and "georef" in config and "sfm" in config:
    # issue 17: the DSM's vertical datum checked at the GCP targets (kitegully.dense.datum)
    DENSE_DATUM = bool((config["dense"].get("datum") or {}).get("enabled", False))

    # issue 21: sites with a tiling section match the DSM as one job per tile (dense_tile), merge
    # it window by window (dense_merge), render the orthophoto as tile jobs too (ortho_plan,
    # ortho_tile per tile, ortho_merge) and the shading and summary from the mosaic (dense_finish);
    # other sites keep the single dense_match job.
    DENSE_TILED = "tiling" in config
    DENSE_DSM_RULE = "dense_merge" if DENSE_TILED else "dense_match"
    DENSE_ORTHO_RULE = "ortho_merge" if DENSE_TILED else "dense_match"
    DENSE_MODEL_INPUTS = {
        "model": eresult("georef", "model"),
        "transform": eresult("georef", "transform.json"),
        "sfm_work": eresult("sfm", "work"),  # images/ holds the prepared copies the model names
    }

if "dense" in config and "georef" in config and "sfm" in config and not DENSE_TILED:

    rule dense_match:
        input:
            model=eresult("georef", "model"),
            transform=eresult("georef", "transform.json"),
            sfm_work=eresult("sfm", "work"),  # images/ holds the prepared copies the model names
            **({"site": result("twin", "site.json")} if config["dense"]["extent"] == "site" else {}),
            **({"gcp": INPUTS_GCP, "gcp_residuals": eresult("georef", "gcp_residuals.csv")} if DENSE_DATUM else {}),
        output:
            dsm=eresult("dense", "dsm.tif"),
            correlation=eresult("dense", "correlation.tif"),
            orthophoto=eresult("dense", "orthophoto.tif"),
            hillshade=report(eresult("dense", "hillshade.png"), caption=caption("dense_hillshade"), category="Dense matching"),
            openness=report(eresult("dense", "openness.png"), caption=caption("dense_openness"), category="Dense matching"),
            summary=report(eresult("dense", "dense_summary.csv"), caption=caption("dense_summary"), category="Dense matching"),
            **({"datum": eresult("dense", "datum_check.csv")} if DENSE_DATUM else {}),
        params:
            dense=config["dense"],
            crs=config["site"]["crs"],
            gcp_format=config["georef"]["gcp_format"],
            csv_crs=config["georef"]["csv_crs"],
        threads: config["dense"]["threads"]
        log:
            elogfile("dense", "dense_match"),
        benchmark:
            ebenchfile("dense", "dense_match")
        script:
            "../scripts/dense_match.py"

if "dense" in config and "georef" in config and "sfm" in config and DENSE_TILED:
    from kitegully.terrain.tiling import TilingParams as _DenseTilingParams

    _DENSE_TILING = _DenseTilingParams.from_config(config)
    # tile names from the config alone (site extent, tiling.tile_m): no checkpoint; each tile's
    # window is whole matching blocks of dense.tile_cells (kitegully.dense.tiles.dense_tiles)
    DENSE_TILE_NAMES = _DENSE_TILING.names()
    DENSE_TILING_PARAMS = {"tile_m": _DENSE_TILING.tile_m, "width_m": _DENSE_TILING.width_m,
                           "height_m": _DENSE_TILING.height_m}

    wildcard_constraints:
        tile=r"r\d{3}_c\d{3}",

    rule dense_tile:
        input:
            **DENSE_MODEL_INPUTS,
            **({"site": result("twin", "site.json")} if config["dense"]["extent"] == "site" else {}),
        output:
            tile=temp(eresult("dense", "tiles/{tile}.npz")),
        params:
            dense=config["dense"],
            crs=config["site"]["crs"],
            tiling=DENSE_TILING_PARAMS,
        threads: config["dense"]["threads"]
        log:
            elogfile("dense", "dense_tile_{tile}"),
        benchmark:
            ebenchfile("dense", "dense_tile_{tile}")
        script:
            "../scripts/dense_tile.py"

    rule dense_merge:
        input:
            tiles=expand(eresult("dense", "tiles/{tile}.npz"), tile=DENSE_TILE_NAMES, allow_missing=True),
            **({"gcp": INPUTS_GCP, "gcp_residuals": eresult("georef", "gcp_residuals.csv")} if DENSE_DATUM else {}),
        output:
            dsm=eresult("dense", "dsm.tif"),
            correlation=eresult("dense", "correlation.tif"),
            stats=eresult("dense", "tiles/merge_stats.json"),
            **({"datum": eresult("dense", "datum_check.csv")} if DENSE_DATUM else {}),
        params:
            dense=config["dense"],
            crs=config["site"]["crs"],
            gcp_format=config["georef"]["gcp_format"],
            csv_crs=config["georef"]["csv_crs"],
        log:
            elogfile("dense", "dense_merge"),
        benchmark:
            ebenchfile("dense", "dense_merge")
        script:
            "../scripts/dense_merge.py"

    # the orthophoto's two global steps (hole filling at any distance, the finest pyramid level
    # from the whole DSM's median) run once in ortho_plan; each ortho_tile job renders whole
    # blocks of dense.orthophoto.tile_cells / upsample cells as the untiled orthophoto does
    # (kitegully.dense.ortho_tiles): the mosaic equals the untiled orthophoto bit for bit
    rule ortho_plan:
        input:
            **DENSE_MODEL_INPUTS,
            dsm=eresult("dense", "dsm.tif"),
        output:
            filled=temp(eresult("dense", "ortho/dsm_filled.tif")),
            plan=eresult("dense", "ortho/plan.json"),
        params:
            dense=config["dense"],
        log:
            elogfile("dense", "ortho_plan"),
        benchmark:
            ebenchfile("dense", "ortho_plan")
        script:
            "../scripts/dense_ortho_plan.py"

    rule ortho_tile:
        input:
            **DENSE_MODEL_INPUTS,
            filled=eresult("dense", "ortho/dsm_filled.tif"),
            plan=eresult("dense", "ortho/plan.json"),
        output:
            tile=temp(eresult("dense", "ortho/{tile}.npz")),
        params:
            dense=config["dense"],
            tiling=DENSE_TILING_PARAMS,
        threads: config["dense"]["threads"]
        log:
            elogfile("dense", "ortho_tile_{tile}"),
        benchmark:
            ebenchfile("dense", "ortho_tile_{tile}")
        script:
            "../scripts/dense_ortho_tile.py"

    rule ortho_merge:
        input:
            tiles=expand(eresult("dense", "ortho/{tile}.npz"), tile=DENSE_TILE_NAMES, allow_missing=True),
            dsm=eresult("dense", "dsm.tif"),
        output:
            orthophoto=eresult("dense", "orthophoto.tif"),
            stats=eresult("dense", "ortho/merge_stats.json"),
        log:
            elogfile("dense", "ortho_merge"),
        benchmark:
            ebenchfile("dense", "ortho_merge")
        script:
            "../scripts/dense_ortho_merge.py"

    rule dense_finish:
        input:
            dsm=eresult("dense", "dsm.tif"),
            stats=eresult("dense", "tiles/merge_stats.json"),
            ortho_stats=eresult("dense", "ortho/merge_stats.json"),
        output:
            hillshade=report(eresult("dense", "hillshade.png"), caption=caption("dense_hillshade"), category="Dense matching"),
            openness=report(eresult("dense", "openness.png"), caption=caption("dense_openness"), category="Dense matching"),
            summary=report(eresult("dense", "dense_summary.csv"), caption=caption("dense_summary"), category="Dense matching"),
        params:
            dense=config["dense"],
        threads: config["dense"]["threads"]
        log:
            elogfile("dense", "dense_finish"),
        benchmark:
            ebenchfile("dense", "dense_finish")
        script:
            "../scripts/dense_finish.py"

if "dense" in config and "georef" in config and "sfm" in config:
    add_targets(
        epoch_results("dense", "dsm.tif"),
        epoch_results("dense", "orthophoto.tif"),
        epoch_results("dense", "hillshade.png"),
        epoch_results("dense", "openness.png"),
        epoch_results("dense", "dense_summary.csv"),
    )
