"""The orthophoto of a tiled site as Snakemake tile jobs (issue 21): plan, tile, merge.

:func:`kitegully.dense.ortho.orthophoto` renders the grid in blocks of
``ortho_block(upsample, tile_cells)`` DSM cells; each block chooses its views and their
pyramid levels from its own extent, elevation range (block plus the ``overlap_m`` occlusion
margin) and median elevation. Two things are global:

(a) hole filling: a hole takes the nearest valid elevation at *any* distance, and
(b) the finest pyramid level of the image cache comes from the whole filled DSM's median.

:func:`plan_orthophoto` (one small job after ``dense_merge``) decides both once: it fills
the whole DSM (memory O(grid): the float64 DSM, scipy's (2, H, W) int32 nearest-cell
indices and the filled copy, about 24 bytes per cell, ~2 GB at 80 M cells; time O(cells)
seconds) and writes the filled DSM (float32, lossless: every value is one of the DSM's
float32 values) and ``plan.json`` (finest level, block side). Each :func:`render_ortho_tile`
job then reads only its window of whole blocks plus the occlusion margin from the filled DSM
and runs the same ``render_window`` on the same blocks with the same cache level, so its
cells equal the untiled orthophoto's exactly (no rule changes; untiled sites keep the one
call). :func:`merge_ortho_tiles` writes the mosaic window by window into a plain GeoTIFF
with its internal mask and copies it to the COG (GDAL streams the copy and builds the
``average`` overviews), memory O(tile).
"""

from __future__ import annotations

import json
import logging
import time
from pathlib import Path
from typing import Sequence

import numpy as np

from kitegully import InputError
from kitegully.dense.ortho import fill_dsm, finest_level, ortho_block, render_window
from kitegully.dense.stage import DenseParams, peak_memory_mb
from kitegully.dense.views import PyramidCache, ViewSet, read_offset, views_from_reconstruction
from kitegully.io.raster import GridSpec, _profile, read_raster
from kitegully.terrain.tiled_fill import Tile
from kitegully.terrain.tiling import TilingParams, whole_block_tiles

log = logging.getLogger(__name__)


def ortho_tiles(shape: tuple[int, int], params: DenseParams, tiling: TilingParams) -> list[Tile]:
    """Windows of the orthophoto tile jobs on a DSM grid of ``shape``: whole rendering blocks.

    The ``ceil(H/T) x ceil(W/T)`` blocks of :func:`kitegully.dense.ortho.ortho_block` are
    split into the tiling's ``n_rows x n_cols`` near-equal rectangles; names as
    :meth:`TilingParams.names`.

    Parameters
    ----------
    shape : (int, int)
        (rows, cols) of the DSM grid.
    params : DenseParams
        ``orthophoto`` (upsample, tile_cells) sets the block side.
    tiling : TilingParams
        The site's tiling.

    Returns
    -------
    list of Tile
        The tile windows (DSM cells), in row-major order.

    Raises
    ------
    InputError
        More tiles along an axis than rendering blocks.
    """
    oc = params.orthophoto
    return whole_block_tiles(shape, ortho_block(oc.upsample, oc.tile_cells), tiling, "orthophoto", "the DSM",
                             "dense.orthophoto.tile_cells",
                             f"dense.orthophoto.tile_cells {oc.tile_cells} / upsample {oc.upsample}")


def load_views(model_dir: str | Path, transform_json: str | Path | None, image_dir: str | Path) -> ViewSet:
    """The georeferenced model's views (as the dense stage reads them; images are read lazily).

    Parameters
    ----------
    model_dir : path
        Folder of the COLMAP model.
    transform_json : path or None
        The georeferencing stage's ``transform.json`` (its ``offset_m``); None = the model is in site coordinates.
    image_dir : path
        Folder holding the images named as in the model.

    Returns
    -------
    ViewSet
        The oriented images in a local frame (:func:`kitegully.dense.views.views_from_reconstruction`).
    """
    import pycolmap

    rec = pycolmap.Reconstruction(str(model_dir))
    return views_from_reconstruction(rec, image_dir, read_offset(transform_json), where=str(model_dir))


def plan_orthophoto(views: ViewSet, dsm_tif: str | Path, params: DenseParams, filled_tif: str | Path,
                    plan_json: str | Path) -> dict:
    """Fill the merged DSM's holes and choose the finest pyramid level once (the global steps).

    Parameters
    ----------
    views : ViewSet
        The model's views (geometry only; no image is read).
    dsm_tif : path
        The merged DSM.
    params : DenseParams
        ``orthophoto`` (upsample, tile_cells).
    filled_tif, plan_json : path
        Outputs: the filled DSM (float32 GeoTIFF, site elevations) and the plan
        (``finest_level``, ``block_cells``, ``median_z_local_m``, ``peak_memory_mb``).

    Notes
    -----
    Memory O(grid) (about 24 bytes per cell), time O(cells): see the module docstring.
    """
    import rasterio

    t0 = time.perf_counter()
    dsm, grid = read_raster(dsm_tif)
    filled = fill_dsm(dsm)
    del dsm
    oc = params.orthophoto
    zloc = filled - views.offset[2]
    finest = finest_level(views, zloc, grid.refined(oc.upsample).cell)
    med = float(np.median(zloc))
    del zloc
    Path(filled_tif).parent.mkdir(parents=True, exist_ok=True)
    with rasterio.open(filled_tif, "w", **_profile(grid, 1, "float32", float("nan"))) as dst:
        dst.write(filled.astype(np.float32), 1)  # exact: the filled values are the DSM's float32 values
    plan = {"finest_level": finest, "block_cells": ortho_block(oc.upsample, oc.tile_cells), "median_z_local_m": med,
            "seconds": time.perf_counter() - t0, "peak_memory_mb": peak_memory_mb()}
    Path(plan_json).write_text(json.dumps(plan, indent=1), encoding="utf-8")
    log.info("orthophoto plan: finest pyramid level %d (median %.2f m local), blocks of %d cells, %.1f s",
             finest, med, plan["block_cells"], plan["seconds"])
    return plan


def render_ortho_tile(views: ViewSet, filled_tif: str | Path, plan_json: str | Path, params: DenseParams,
                      tiling: TilingParams, tile_name: str, out_npz: str | Path,
                      arrays: list[np.ndarray] | None = None) -> dict:
    """Render one orthophoto tile (whole blocks of the untiled rendering) and save it.

    Reads the filled DSM over the tile's window plus the occlusion margin
    ``ceil(orthophoto.overlap_m / cell)`` cells (clipped to the grid) and the plan's finest
    level. ``out_npz``: ``image`` (B, h*up, w*up) uint8, ``source`` int16 and ``meta`` (JSON).
    Memory O((window + 2 margin)^2) plus the image cache; cost as the untiled rendering
    of the window.

    Parameters
    ----------
    views : ViewSet
        The model's views.
    filled_tif : path
        The filled DSM of :func:`plan_orthophoto` (site elevations).
    plan_json : path
        The plan of :func:`plan_orthophoto` (``finest_level``, ``block_cells``).
    params : DenseParams
        ``orthophoto`` (upsample, tile_cells, overlap_m, occlusion_tolerance_m) and ``max_cached_images``.
    tiling : TilingParams
        The site's tiling.
    tile_name : str
        Name of the tile to render (:func:`ortho_tiles`).
    out_npz : path
        Output file.
    arrays : list of ndarray or None
        Images in memory instead of the files (tests); None = read the image files.

    Returns
    -------
    dict
        The tile's ``meta``: ``tile`` (name), window (``r0, c0, h, w``, DSM cells), ``upsample``, ``seconds``,
        ``peak_memory_mb`` and the DSM ``grid``.

    Raises
    ------
    InputError
        ``tile_name`` is not in the tiling, or the plan's ``block_cells`` is not that of ``dense.orthophoto``.
    """
    import rasterio
    from rasterio.windows import Window

    t0 = time.perf_counter()
    plan = json.loads(Path(plan_json).read_text(encoding="utf-8"))
    oc = params.orthophoto
    with rasterio.open(filled_tif) as src:
        grid = GridSpec.from_transform(src.transform, src.width, src.height, src.crs.to_string())
        tiles = {t.name: t for t in ortho_tiles(grid.shape, params, tiling)}
        if tile_name not in tiles:
            raise InputError(f"tile {tile_name}: not in the {tiling.counts[0]} x {tiling.counts[1]} grid of tiling.tile_m {tiling.tile_m:g}")
        t = tiles[tile_name]
        if plan["block_cells"] != ortho_block(oc.upsample, oc.tile_cells):
            raise InputError(f"{plan_json}: block_cells {plan['block_cells']} is not that of dense.orthophoto (stale plan?)")
        marg = int(np.ceil(oc.overlap_m / grid.cell))
        ra, rb = max(0, t.r0 - marg), min(grid.height, t.r0 + t.h + marg)
        ca, cb = max(0, t.c0 - marg), min(grid.width, t.c0 + t.w + marg)
        z = src.read(1, window=Window(ca, ra, cb - ca, rb - ra)).astype(np.float64)
    zloc = z - views.offset[2]
    finest = int(plan["finest_level"])
    cache = PyramidCache(views, params.max_cached_images, arrays, min_level=finest)
    img, source = render_window(views, zloc, (ra, ca), grid, (t.r0, t.r0 + t.h), (t.c0, t.c0 + t.w), cache, finest,
                                oc.upsample, plan["block_cells"], oc.overlap_m, oc.occlusion_tolerance_m)
    meta = {"tile": t.name, "r0": t.r0, "c0": t.c0, "h": t.h, "w": t.w, "upsample": oc.upsample,
            "seconds": time.perf_counter() - t0, "peak_memory_mb": peak_memory_mb(),
            "grid": {"transform": list(grid.transform)[:6], "width": grid.width, "height": grid.height}}
    Path(out_npz).parent.mkdir(parents=True, exist_ok=True)
    np.savez(out_npz, image=img, source=source, meta=np.array(json.dumps(meta)))
    log.info("orthophoto tile %s: DSM rows %d+%d, cols %d+%d, %.1f s, %.1f%% filled", t.name, t.r0, t.h, t.c0, t.w,
             meta["seconds"], 100 * float((source >= 0).mean()))
    return meta


def merge_ortho_tiles(tile_files: Sequence[str | Path], dsm_tif: str | Path, out_tif: str | Path,
                      stats_json: str | Path) -> dict:
    """Write the orthophoto COG from the tile jobs, window by window (memory O(tile)).

    The tiles go into a plain tiled GeoTIFF with the internal mask band (True where an image
    saw the cell), which GDAL's COG driver then copies with ``average`` overviews, as
    :func:`kitegully.io.raster.write_raster` makes the untiled orthophoto. ``stats_json``:
    ``orthophoto_s`` (sum of the tile jobs' rendering time), ``tile_jobs``, ``tile_peak_memory_mb``, ``merge_peak_memory_mb``.

    Parameters
    ----------
    tile_files : sequence of path
        The ``.npz`` files of :func:`render_ortho_tile`, one per tile.
    dsm_tif : path
        The merged DSM; its grid is refined by the tiles' ``upsample`` to the orthophoto grid.
    out_tif : path
        The orthophoto COG.
    stats_json : path
        Output file of the statistics.

    Returns
    -------
    dict
        The statistics written to ``stats_json``: ``orthophoto_s``, ``tile_jobs``, ``tile_peak_memory_mb`` (MB,
        largest over the tiles) and ``merge_peak_memory_mb`` (MB).

    Raises
    ------
    InputError
        The tiles disagree with the DSM grid or on ``upsample``, or their cells do not add up to the grid's.
    """
    import rasterio
    import rasterio.shutil
    from rasterio.windows import Window

    with rasterio.open(dsm_tif) as src:
        grid0 = GridSpec.from_transform(src.transform, src.width, src.height, src.crs.to_string())
    metas, covered = [], 0
    for p in tile_files:
        with np.load(p) as z:
            metas.append(json.loads(str(z["meta"])))
    up = {m["upsample"] for m in metas}
    if len(up) != 1 or any(m["grid"]["width"] != grid0.width or m["grid"]["height"] != grid0.height for m in metas):
        raise InputError(f"{tile_files[0]}: the orthophoto tiles disagree with {dsm_tif} (stale tiles of another run?)")
    covered = sum(m["h"] * m["w"] for m in metas)
    if covered != grid0.width * grid0.height:
        raise InputError(f"{tile_files[0]}: the {len(metas)} orthophoto tiles cover {covered} cells, the grid {grid0.width * grid0.height}")
    u = up.pop()
    og = grid0.refined(u)
    with np.load(tile_files[0]) as z:
        nb = z["image"].shape[0]
    out_tif = Path(out_tif)
    out_tif.parent.mkdir(parents=True, exist_ok=True)
    tmp = out_tif.with_name(out_tif.stem + ".stream.tif")
    names = ["R", "G", "B", "NIR"][:nb] if nb >= 3 else ["grey"] * nb
    try:
        with rasterio.Env(GDAL_TIFF_INTERNAL_MASK=True):
            with rasterio.open(tmp, "w", **_profile(og, nb, "uint8", None)) as dst:
                for p, m in zip(tile_files, metas):
                    with np.load(p) as z:
                        img, src_idx = z["image"], z["source"]
                    win = Window(m["c0"] * u, m["r0"] * u, m["w"] * u, m["h"] * u)
                    dst.write(img, window=win)
                    dst.write_mask(np.where(src_idx >= 0, 255, 0).astype(np.uint8), window=win)
                dst.descriptions = tuple(names)
            rasterio.shutil.copy(tmp, out_tif, driver="COG", compress="deflate", predictor="no", blocksize=256,
                                 overviews="auto", overview_resampling="average", bigtiff="IF_SAFER")
    finally:
        tmp.unlink(missing_ok=True)
    stats = {"orthophoto_s": float(sum(m["seconds"] for m in metas)), "tile_jobs": len(metas),
             "tile_peak_memory_mb": float(max(m["peak_memory_mb"] for m in metas)), "merge_peak_memory_mb": peak_memory_mb()}
    Path(stats_json).write_text(json.dumps(stats, indent=1), encoding="utf-8")
    log.info("orthophoto merge: %d tiles, %d x %d cells", len(metas), og.width, og.height)
    return stats
