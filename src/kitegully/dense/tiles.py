"""Dense matching of a large site as Snakemake tile jobs (issue 21): tile, merge, finish.

A site that sets ``tiling:`` runs :func:`match_dense_tile` once per tile of
:class:`kitegully.terrain.tiling.TilingParams` (one Snakemake job each), then
:func:`merge_dense_tiles` writes ``dsm.tif`` and ``correlation.tif`` window by window
(memory O(tile)) and checks the vertical datum, and :func:`finish_dense_surface` renders the
relief shading from the merged DSM and writes the stage summary (the orthophoto is tiled
too: :mod:`kitegully.dense.ortho_tiles`). Untiled
sites keep the single job of :func:`kitegully.dense.stage.match_dense_surface`.

Why the tiled DSM equals the untiled one
----------------------------------------
:func:`kitegully.dense.surface.dense_surface` already matches the grid block by block: a
block of ``T`` cells (``dense.tile_cells`` rounded up to a multiple of the coarsest pyramid
factor ``f = 2**(levels-1)``) is matched on itself plus a halo of ``O`` cells
(``dense.overlap_cells`` rounded up to a multiple of ``f``) and only its core is kept; its
elevation bounds come from the tie points inside that box, its image pyramids from a cache
whose finest level depends on all views. Nothing else crosses blocks: no filter runs on the
assembled DSM. A tile job here is a rectangle of whole blocks (the block grid is split into
the tiling's ``n_rows x n_cols`` near-equal parts), and it runs ``dense_surface`` on the
sub-grid of its window, whose blocks start at the same cells as the untiled run's. So each
block sees the same cells, halo, elevation bounds and images, and the mosaic equals the
untiled DSM up to the rounding of the cell-centre coordinates (computed from the window's
origin instead of the grid's, ~1e-10 m). The halo each job reads is the matcher's own: ``O``
cells on every side of every block ([I] ``O`` covers the correlation window at the coarsest
level, ``window_half_cells x f`` cells, and lets the SGM paths enter a block from real
neighbours), so the job's total halo is ``O`` around its window.
"""

from __future__ import annotations

import json
import logging
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Mapping, Sequence

import numpy as np
import pandas as pd

from kitegully import InputError
from kitegully.dense.cell import choose_cell
from kitegully.dense.datum import check_datum
from kitegully.dense.stage import DenseParams, peak_memory_mb, shading_figures, site_grid
from kitegully.dense.surface import DenseResult, dense_surface
from kitegully.dense.views import ViewSet, read_offset, views_from_reconstruction
from kitegully.io.raster import GridSpec, _profile, read_raster
from kitegully.io.tables import write_table
from kitegully.terrain.tiled_fill import Tile
from kitegully.terrain.tiling import TilingParams, whole_block_tiles

if TYPE_CHECKING:
    from kitegully.dense.cell import CellChoice

log = logging.getLogger(__name__)

NCC_BINS = 20000  # median NCC from a histogram of 1e-4 wide bins over -1..1 (memory O(1) per tile)


def matching_block(params: DenseParams) -> tuple[int, int]:
    """Block side ``T`` and halo ``O`` (cells) of :func:`kitegully.dense.surface.dense_surface`.

    Both are rounded up to a multiple of the coarsest pyramid factor ``2**(levels-1)``, as
    ``dense_surface`` does, so tile windows made of whole blocks align with its blocks.
    """
    f = 2 ** (params.matching.levels - 1)
    return max(f, int(np.ceil(params.tile_cells / f)) * f), int(np.ceil(params.overlap_cells / f)) * f


def dense_tiles(shape: tuple[int, int], params: DenseParams, tiling: TilingParams) -> list[Tile]:
    """Windows of the dense tile jobs on a DSM grid of ``shape``: whole matching blocks.

    The grid's ``ceil(H/T) x ceil(W/T)`` blocks are split into the tiling's
    ``n_rows x n_cols`` near-equal rectangles (:func:`kitegully.terrain.tiling.split_grid`);
    the last row and column of blocks are clipped to the grid. The tile names
    (``r000_c000`` ...) are those of :meth:`TilingParams.names`.

    Parameters
    ----------
    shape : (int, int)
        (rows, cols) of the DSM grid.
    params : DenseParams
        ``tile_cells`` and ``matching.levels`` set the block side (:func:`matching_block`).
    tiling : TilingParams
        The site's tiling.

    Returns
    -------
    list of Tile
        The tile windows (DSM cells), in row-major order.

    Raises
    ------
    InputError
        More tiles along an axis than matching blocks.
    """
    T, _ = matching_block(params)
    return whole_block_tiles(shape, T, tiling, "dense", "the DSM", "dense.tile_cells", f"dense.tile_cells {T} (matching)")


def load_views_and_grid(model_dir: str | Path, transform_json: str | Path | None, image_dir: str | Path, crs: str,
                        params: DenseParams,
                        site_json: str | Path | None = None) -> tuple[ViewSet, CellChoice, DenseParams, GridSpec]:
    """The model's views, the cell choice, the resolved parameters and the DSM grid (as the untiled stage).

    Returns ``(views, cell, params, grid)``; deterministic, so every tile job finds the same grid.

    Parameters
    ----------
    model_dir : path
        Georeferenced COLMAP model folder (local frame).
    transform_json : path or None
        The georef stage's ``transform.json`` (offset of the local frame); None = no offset.
    image_dir : path
        Folder of the prepared images the model names.
    crs : str
        Site CRS.
    params : DenseParams
        The stage's parameters (``cell_m`` may be ``auto``).
    site_json : path or None
        The twin's ``site.json`` (needed by ``extent: site``).

    Returns
    -------
    views : ViewSet
        The oriented images.
    cell : CellChoice
        The DSM cell and how it was chosen.
    params : DenseParams
        ``params`` with ``cell_m`` set to the chosen cell (m).
    grid : GridSpec
        The DSM grid (site CRS).

    Raises
    ------
    InputError
        ``model_dir`` is not a COLMAP model folder.
    """
    import pycolmap

    model_dir = Path(model_dir)
    if not (model_dir / "images.bin").exists() and not (model_dir / "images.txt").exists():
        raise InputError(f"{model_dir}: not a COLMAP model folder (no images.bin or images.txt)")
    rec = pycolmap.Reconstruction(str(model_dir))
    views = views_from_reconstruction(rec, image_dir, read_offset(transform_json), where=str(model_dir))
    cell = choose_cell(params.cell_m, views, params.matching.window_half_cells)
    params = replace(params, cell_m=cell.cell_m)
    return views, cell, params, site_grid(views, params, crs, site_json)


def _grid_meta(grid: GridSpec) -> dict:
    return {"transform": list(grid.transform)[:6], "width": grid.width, "height": grid.height, "crs": grid.crs}


def _grid_from_meta(m: Mapping) -> GridSpec:
    from affine import Affine

    return GridSpec.from_transform(Affine(*m["transform"]), int(m["width"]), int(m["height"]), m["crs"])


def match_dense_tile(model_dir: str | Path, transform_json: str | Path | None, image_dir: str | Path, crs: str,
                     params: DenseParams, tiling: TilingParams, tile_name: str, threads: int, out_npz: str | Path,
                     site_json: str | Path | None = None) -> dict:
    """Match one dense tile (its window of whole matching blocks, each with its halo) and save it.

    Parameters
    ----------
    model_dir, transform_json, image_dir, crs, params, site_json
        As :func:`kitegully.dense.stage.match_dense_surface`.
    tiling : TilingParams
        The site's tiling (the tile counts).
    tile_name : str
        The tile (``r000_c000``...).
    threads : int
        Threads granted to the job (numba).
    out_npz : path
        Output: ``dsm`` (site elevations before the datum check, float32, NaN = no value),
        ``ncc`` (float32), ``nseen`` (int16, images whose frame holds the cell) on the
        window, and ``meta`` (JSON: grid, window, timings, cell choice).

    Returns
    -------
    dict
        The tile's metadata.

    Notes
    -----
    Cost O(window cells x labels x views), memory O((window + 2 O)^2) plus the image cache.
    """
    import numba

    numba.set_num_threads(max(1, min(int(threads), numba.config.NUMBA_NUM_THREADS)))
    views, cell, params, grid = load_views_and_grid(model_dir, transform_json, image_dir, crs, params, site_json)
    tiles = {t.name: t for t in dense_tiles(grid.shape, params, tiling)}
    if tile_name not in tiles:
        raise InputError(f"tile {tile_name}: not in the {tiling.counts[0]} x {tiling.counts[1]} grid of tiling.tile_m {tiling.tile_m:g}")
    t = tiles[tile_name]
    res = match_tile_window(views, grid, t, params)
    return save_dense_tile(out_npz, res, t, grid, params, {"images": len(views.images), "gsd_measured_m": cell.gsd_m})


def match_tile_window(views: ViewSet, grid: GridSpec, tile: Tile, params: DenseParams,
                      arrays: list[np.ndarray] | None = None) -> DenseResult:
    """Match the window of ``tile`` (whole blocks of :func:`dense_tiles`) on the site grid ``grid``.

    Runs :func:`kitegully.dense.surface.dense_surface` on the sub-grid of the window, so its
    blocks (each with its ``O``-cell halo) are those of the untiled run (module docstring).
    ``arrays`` optionally gives the images in memory. Cost O(window cells x labels x views).

    Parameters
    ----------
    views : ViewSet
        The oriented images.
    grid : GridSpec
        The site's DSM grid.
    tile : Tile
        The window (cells of ``grid``); its origin must lie on the matching blocks.
    params : DenseParams
        ``matching``, ``tile_cells``, ``overlap_cells`` and ``max_cached_images``.
    arrays : list of ndarray or None
        Images in memory; None = read the image files.

    Returns
    -------
    DenseResult
        The window's DSM (site elevations), NCC and image counts.

    Raises
    ------
    ValueError
        The tile's origin is not on the matching blocks.
    """
    T, _ = matching_block(params)
    if tile.r0 % T or tile.c0 % T:
        raise ValueError(f"tile {tile.name}: origin ({tile.r0}, {tile.c0}) is not on the {T}-cell matching blocks")
    return dense_surface(views, grid.window(tile.r0, tile.c0, tile.h, tile.w), params.matching, params.tile_cells,
                         params.overlap_cells, params.max_cached_images, arrays)


def save_dense_tile(out_npz: str | Path, res: DenseResult, tile: Tile, grid: GridSpec, params: DenseParams,
                    extra: Mapping | None = None) -> dict:
    """Save one tile job's result (``dsm``, ``ncc``, ``nseen`` and the JSON ``meta``) for :func:`merge_dense_tiles`.

    Parameters
    ----------
    out_npz : path
        Output file.
    res : DenseResult
        The window's result (:func:`match_tile_window`).
    tile : Tile
        Its window.
    grid : GridSpec
        The site's DSM grid.
    params : DenseParams
        The stage's parameters (block side and halo: :func:`matching_block`).
    extra : mapping or None
        Further ``meta`` entries (``images``, ``gsd_measured_m``); they override the defaults.

    Returns
    -------
    dict
        The ``meta``: window, block side, halo, blocks, matching time (s), cell (m), grid, peak memory (MB)
        and ``extra``.
    """
    T, O = matching_block(params)
    meta = {"tile": tile.name, "r0": tile.r0, "c0": tile.c0, "h": tile.h, "w": tile.w, "block_cells": T,
            "halo_cells": O, "blocks": res.tiles, "matching_s": res.seconds, "images": 0, "gsd_measured_m": float("nan"),
            "cell_m": grid.cell, "grid": _grid_meta(grid), "peak_memory_mb": peak_memory_mb(), **(extra or {})}
    Path(out_npz).parent.mkdir(parents=True, exist_ok=True)
    np.savez(out_npz, dsm=res.dsm, ncc=res.ncc, nseen=res.nseen, meta=np.array(json.dumps(meta)))
    log.info("dense tile %s: rows %d+%d, cols %d+%d (%d blocks of %d cells, halo %d): %.1f s, %.1f%% valid",
             tile.name, tile.r0, tile.h, tile.c0, tile.w, res.tiles, T, O, res.seconds,
             100 * float(np.isfinite(res.dsm).mean()))
    return meta


def _tile_meta(path: str | Path) -> dict:
    with np.load(path) as z:
        return json.loads(str(z["meta"]))


def merge_dense_tiles(tile_files: Sequence[str | Path], params: DenseParams, out: Mapping[str, str | Path],
                      gcps: pd.DataFrame | None = None) -> dict:
    """Mosaic the tile jobs' DSM and correlation window by window; check the datum; write the stats.

    Parameters
    ----------
    tile_files : paths
        The ``.npz`` of every tile job (:func:`match_dense_tile`).
    params : DenseParams
        The stage's parameters (``datum``).
    out : mapping
        ``dsm``, ``correlation`` (GeoTIFFs, tiled and compressed, streamed), ``stats``
        (JSON of the mosaic's coverage and timings, for :func:`finish_dense_surface`) and,
        with the datum check, ``datum`` (per-target table).
    gcps : DataFrame, optional
        Targets for the datum check (``params.datum.enabled``).

    Returns
    -------
    dict
        The statistics written to ``out["stats"]``.

    Notes
    -----
    Memory O(tile): the DSM is assembled in a disk-backed array (``numpy.memmap``) that the
    datum check reads only around the targets; the outputs are written one tile at a time.
    Time O(cells).
    """
    import rasterio
    from rasterio.windows import Window

    metas = [_tile_meta(p) for p in tile_files]
    grids = {json.dumps(m["grid"], sort_keys=True) for m in metas}
    if len(grids) != 1:
        raise InputError(f"{tile_files[0]}: the dense tiles disagree on the DSM grid (stale tiles of another run?)")
    grid = _grid_from_meta(metas[0]["grid"])
    covered = sum(m["h"] * m["w"] for m in metas)
    if covered != grid.width * grid.height:
        raise InputError(f"{tile_files[0]}: the {len(metas)} dense tiles cover {covered} cells, the grid {grid.width * grid.height}")
    dsm_path = Path(out["dsm"])
    dsm_path.parent.mkdir(parents=True, exist_ok=True)
    raw_path = dsm_path.with_name(dsm_path.stem + ".raw.npy")
    raw = np.lib.format.open_memmap(raw_path, mode="w+", dtype=np.float32, shape=(grid.height, grid.width))
    hist = np.zeros(NCC_BINS, np.int64)
    n_valid = n_seen2 = n_valid_seen2 = 0
    try:
        with rasterio.open(out["correlation"], "w", **_profile(grid, 1, "float32", float("nan"))) as dst:
            dst.update_tags(units="NCC (-1..1)")
            for p, m in zip(tile_files, metas):
                with np.load(p) as z:
                    d, c, s = z["dsm"], z["ncc"], z["nseen"]
                raw[m["r0"]:m["r0"] + m["h"], m["c0"]:m["c0"] + m["w"]] = d
                dst.write(c.astype(np.float32), 1, window=Window(m["c0"], m["r0"], m["w"], m["h"]))
                ok = np.isfinite(d)
                n_valid += int(ok.sum())
                n_seen2 += int((s >= 2).sum())
                n_valid_seen2 += int((ok & (s >= 2)).sum())
                cf = c[np.isfinite(c)]
                hist += np.bincount(np.clip(((cf + 1.0) * NCC_BINS / 2).astype(np.int64), 0, NCC_BINS - 1),
                                    minlength=NCC_BINS)
        raw.flush()
        if n_valid == 0:
            raise InputError(f"{tile_files[0]}: dense matching found no valid cell in any tile")
        offset, datum = 0.0, None
        if params.datum.enabled:
            if gcps is None:
                raise InputError("dense.datum.enabled: the datum check needs the GCP file (the rule's gcp input)")
            datum = check_datum(raw, grid, gcps, params.datum)  # reads the memmap only around the targets
            log.info("dense: %s", datum.reason)
            if datum.applied:
                offset = float(datum.offset_m)
            if "datum" in out:
                write_table(datum.table, out["datum"])
        with rasterio.open(dsm_path, "w", **_profile(grid, 1, "float32", float("nan"))) as dst:
            dst.update_tags(units="m", nodata="NaN")
            for m in metas:
                win = np.asarray(raw[m["r0"]:m["r0"] + m["h"], m["c0"]:m["c0"] + m["w"]])
                if offset:
                    win = win - np.float32(offset)  # as the untiled stage: float32 minus float32 offset
                dst.write(win, 1, window=Window(m["c0"], m["r0"], m["w"], m["h"]))
    finally:
        del raw
        raw_path.unlink(missing_ok=True)
    cells = grid.width * grid.height
    cum = np.cumsum(hist)
    med_bin = int(np.searchsorted(cum, 0.5 * cum[-1])) if cum[-1] else -1
    stats = {
        "images": metas[0]["images"], "cell_m": grid.cell, "gsd_measured_m": metas[0]["gsd_measured_m"],
        "width_cells": grid.width, "height_cells": grid.height, "area_km2": cells * grid.cell ** 2 / 1e6,
        "tiles": sum(m["blocks"] for m in metas), "tile_jobs": len(metas),
        "seen_by_2_or_more_pct": 100.0 * n_seen2 / cells, "valid_pct": 100.0 * n_valid / cells,
        "coverage_of_seen_pct": 100.0 * n_valid_seen2 / n_seen2 if n_seen2 else float("nan"),
        "median_ncc": (med_bin + 0.5) * 2.0 / NCC_BINS - 1.0 if med_bin >= 0 else float("nan"),
        "matching_s": float(sum(m["matching_s"] for m in metas)),
        "tile_peak_memory_mb": float(max(m["peak_memory_mb"] for m in metas)),
        "applied_offset_m": offset,
    }
    if datum is not None:
        stats["datum"] = datum.summary()
    Path(out["stats"]).write_text(json.dumps(stats, indent=1), encoding="utf-8")
    log.info("dense merge: %d tiles, %d x %d cells, %.1f%% valid, datum offset %+.3f m",
             len(metas), grid.width, grid.height, stats["valid_pct"], offset)
    return stats


def finish_dense_surface(dsm_tif: str | Path, stats_json: str | Path, ortho_stats_json: str | Path,
                         params: DenseParams, threads: int, out: Mapping[str, str | Path]) -> dict:
    """Shading figures and stage summary of a tiled site from the merged DSM and the tile jobs' stats.

    ``out`` keys: hillshade, openness, summary (the untiled stage's, less the orthophoto,
    which the ``ortho_tile`` jobs render and ``ortho_merge`` writes:
    :mod:`kitegully.dense.ortho_tiles`). The summary has the untiled stage's rows;
    ``matching_s`` and ``orthophoto_s`` sum the tile jobs' times (the CPU-bound parts,
    whatever ran in parallel) and ``median_ncc`` is read from a histogram (±5e-5). Memory
    O(grid): the shading reads the whole DSM. Cost O(cells).

    Parameters
    ----------
    dsm_tif : path
        The merged DSM.
    stats_json : path
        The statistics of :func:`merge_dense_tiles`.
    ortho_stats_json : path
        The statistics of :func:`kitegully.dense.ortho_tiles.merge_ortho_tiles`.
    params : DenseParams
        ``shading`` and ``figure_max_px``.
    threads : int
        Threads granted to the rule (written to the summary).
    out : mapping
        Product name → path; keys hillshade, openness, summary.

    Returns
    -------
    dict
        The summary written to ``out["summary"]``.
    """
    stats = json.loads(Path(stats_json).read_text(encoding="utf-8"))
    ortho = json.loads(Path(ortho_stats_json).read_text(encoding="utf-8"))
    dsm, grid = read_raster(dsm_tif)
    t_ortho = ortho["orthophoto_s"]
    shading_figures(dsm, grid, params.shading, params.figure_max_px, out["hillshade"], out["openness"])
    keys = ("images", "cell_m", "gsd_measured_m", "width_cells", "height_cells", "area_km2", "tiles",
            "seen_by_2_or_more_pct", "valid_pct", "coverage_of_seen_pct", "median_ncc", "matching_s")
    summary = {k: stats[k] for k in keys}
    cells = stats["width_cells"] * stats["height_cells"]
    summary.update({"orthophoto_s": t_ortho, "cells_per_s": cells / stats["matching_s"],
                    "peak_memory_mb": max(peak_memory_mb(), stats["tile_peak_memory_mb"], ortho["tile_peak_memory_mb"]),
                    "threads": int(threads),
                    "tile_jobs": stats["tile_jobs"]})
    summary.update(stats.get("datum", {}))
    summary["extrapolated_3_18_km2_at_0_2_m_h"] = 3.18e6 / 0.2 ** 2 / summary["cells_per_s"] / 3600.0
    write_table(pd.DataFrame({"quantity": list(summary), "value": [summary[k] for k in summary]}), out["summary"])
    log.info("dense (tiled): %d tile jobs, %.1f%% of the cells seen by >= 2 images valid; %.0f cells/s",
             stats["tile_jobs"], summary["coverage_of_seen_pct"], summary["cells_per_s"])
    return summary
