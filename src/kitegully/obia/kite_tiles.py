"""The kite-scale bare-soil map as Snakemake tile jobs (issue 21): histogram tiles, map tiles, merge.

:func:`kitegully.obia.kite.bare_soil_map` works in blocks of ``tile_cells`` cells (each
read with a halo of the index blur plus the slope window; segments never cross a block)
and one global threshold from the fine histogram of every block. A tiled site splits
those same blocks into ``tiling`` tile jobs of whole blocks (:func:`kite_tiles`):

1. ``obia_kite_histogram`` (per tile): the fine histogram of the tile's blocks (counts by
   local range and one-DN index steps, :class:`kitegully.obia.threshold.IndexHistogram`);
2. ``obia_kite_tile`` (per tile): the global threshold from the sum of all tiles' histograms
   (integers: exact in any order), then each block segmented and classified exactly as
   the untiled map does it;
3. ``obia_kite_merge``: the tiles' cores written into the map, the polygons, the figure
   and the threshold record.

Each block's classes depend only on its own read window and the global threshold, so the
merged map equals the untiled one cell for cell (tests/obia/test_kite_tiles.py), and the
threshold record is the same. Memory per tile job: a few block-sized arrays (as untiled);
the merge holds the uint8 map once (polygons and figure need it whole).
"""

from __future__ import annotations

import json
import logging
from pathlib import Path
from typing import Sequence

import numpy as np
import rasterio
from rasterio.windows import Window

from kitegully import InputError
from kitegully.io.raster import _profile
from kitegully.obia.classify import NODATA
from kitegully.obia.kite import (block_histogram, classify_block, global_threshold, histogram_edges, open_kite_inputs,
                                 unimodal_code)
from kitegully.obia.scene import ObiaParams
from kitegully.obia.threshold import FINE_BINS_PER_BIN, IndexHistogram, ThresholdResult
from kitegully.terrain.tiled_fill import Tile
from kitegully.terrain.tiling import TilingParams, whole_block_tiles

log = logging.getLogger(__name__)


def kite_tiles(shape: tuple[int, int], tile_cells: int, tiling: TilingParams) -> list[Tile]:
    """Windows of the kite-map tile jobs on an orthophoto of ``shape``: whole blocks of ``tile_cells``.

    The ``ceil(H/T) x ceil(W/T)`` blocks of the untiled map are split into the tiling's
    ``n_rows x n_cols`` near-equal rectangles of blocks; names as :meth:`TilingParams.names`.

    Parameters
    ----------
    shape : tuple of int
        Orthophoto size (rows, cols).
    tile_cells : int
        Block side (cells).
    tiling : TilingParams
        The site's tiling.

    Returns
    -------
    list of Tile
        Tile windows in row-major order.

    Raises
    ------
    InputError
        More tiles along an axis than blocks.
    """
    return whole_block_tiles(shape, tile_cells, tiling, "kite-map", "the orthophoto", "obia.kite_scale.tile_cells",
                             f"obia.kite_scale.tile_cells {tile_cells}")


def _blocks(tile: Tile, shape: tuple[int, int], tile_cells: int, halo: int) -> list[tuple[Window, Window]]:
    """(read, core) windows of the untiled map's blocks inside ``tile``, in the untiled order."""
    h, w = shape
    out = []
    for r0 in range(tile.r0, tile.r0 + tile.h, tile_cells):
        for c0 in range(tile.c0, tile.c0 + tile.w, tile_cells):
            bh, bw = min(tile_cells, h - r0), min(tile_cells, w - c0)
            rr0, cc0 = max(0, r0 - halo), max(0, c0 - halo)
            rr1, cc1 = min(h, r0 + bh + halo), min(w, c0 + bw + halo)
            out.append((Window(cc0, rr0, cc1 - cc0, rr1 - rr0), Window(c0, r0, bw, bh)))
    return out


def _tile_of(name: str, shape: tuple[int, int], tile_cells: int, tiling: TilingParams) -> Tile:
    for t in kite_tiles(shape, tile_cells, tiling):
        if t.name == name:
            return t
    raise InputError(f"tile {name}: not in the {tiling.counts[0]} x {tiling.counts[1]} grid of tiling.tile_m {tiling.tile_m:g}")


def kite_histogram_tile(ortho_path: str | Path, dsm_path: str | Path, out_npz: str | Path, params: ObiaParams,
                        tile_cells: int, tiling: TilingParams, name: str, nir_path: str | Path | None = None) -> int:
    """Fine histogram of tile ``name``'s blocks, saved in ``out_npz`` (:meth:`IndexHistogram.save`); returns the cells counted.

    O(tile cells).

    Parameters
    ----------
    ortho_path : path
        RGB orthophoto (bands 1-3).
    dsm_path : path
        DSM covering the orthophoto.
    out_npz : path
        Output file; also holds the tile window ``r0, c0, h, w`` (cells).
    params : ObiaParams
        Method parameters.
    tile_cells : int
        Block side (cells).
    tiling : TilingParams
        The site's tiling.
    name : str
        Tile name.
    nir_path : path or None
        NIR orthophoto on the RGB orthophoto's grid.

    Returns
    -------
    int
        Cells counted in the histogram.
    """
    with open_kite_inputs(ortho_path, dsm_path, nir_path, params, tile_cells) as (ortho, dsm, nir, grid, halo):
        shape = (grid.height, grid.width)
        tile = _tile_of(name, shape, tile_cells, tiling)
        edges = histogram_edges(params)
        hist = IndexHistogram.zeros(params.hist_bins * FINE_BINS_PER_BIN)
        for read, core in _blocks(tile, shape, tile_cells, halo):
            hist += block_histogram(ortho, dsm, nir, read, core, params, str(ortho_path), edges)
    Path(out_npz).parent.mkdir(parents=True, exist_ok=True)
    hist.save(out_npz, r0=tile.r0, c0=tile.c0, h=tile.h, w=tile.w)
    n = int(hist.by_range.sum())
    log.info("tile %s: histogram of %d cells", name, n)
    return n


def merged_threshold(hist_files: Sequence[str | Path], params: ObiaParams) -> ThresholdResult:
    """The global threshold from the sum of the tiles' histograms (exact: integer sums)."""
    hist = IndexHistogram.zeros(params.hist_bins * FINE_BINS_PER_BIN)
    for f in hist_files:
        try:
            tile = IndexHistogram.load(f)
        except KeyError:
            raise InputError(f"{f}: histogram tile without local ranges and one-DN index steps (written by an older "
                             "version); rerun rule obia_kite_histogram") from None
        if tile.by_range.shape != hist.by_range.shape:
            raise InputError(f"{f}: histogram of {tile.by_range.shape[0]} bins, expected {hist.by_range.shape[0]} "
                             "(obia parameters changed?)")
        hist += tile
    return global_threshold(hist, params)


def kite_map_tile(ortho_path: str | Path, dsm_path: str | Path, hist_files: Sequence[str | Path], out_npz: str | Path,
                  params: ObiaParams, tile_cells: int, tiling: TilingParams, name: str,
                  nir_path: str | Path | None = None) -> int:
    """Classes (0 vegetated, 1 bare, 255 no data) of tile ``name``, saved with its window and water cells.

    Returns the water cells of the tile. O(tile cells · log).

    Parameters
    ----------
    ortho_path : path
        RGB orthophoto (bands 1-3).
    dsm_path : path
        DSM covering the orthophoto.
    hist_files : sequence of path
        Every tile's histogram file (:func:`kite_histogram_tile`).
    out_npz : path
        Output file: ``classes``, the tile origin ``r0, c0`` (cells) and ``water_cells``.
    params : ObiaParams
        Method parameters.
    tile_cells : int
        Block side (cells).
    tiling : TilingParams
        The site's tiling.
    name : str
        Tile name.
    nir_path : path or None
        NIR orthophoto on the RGB orthophoto's grid.

    Returns
    -------
    int
        Cells of the tile masked as open water.
    """
    thr = merged_threshold(hist_files, params)
    unimodal = unimodal_code(params)
    with open_kite_inputs(ortho_path, dsm_path, nir_path, params, tile_cells) as (ortho, dsm, nir, grid, halo):
        shape = (grid.height, grid.width)
        tile = _tile_of(name, shape, tile_cells, tiling)
        classes = np.full((tile.h, tile.w), NODATA, np.uint8)
        water = 0
        blocks = _blocks(tile, shape, tile_cells, halo)
        for i, (read, core) in enumerate(blocks):
            out, wet = classify_block(ortho, dsm, nir, read, core, params, str(ortho_path), grid.cell, thr.valley, unimodal)
            classes[core.row_off - tile.r0:core.row_off - tile.r0 + core.height,
                    core.col_off - tile.c0:core.col_off - tile.c0 + core.width] = out
            water += wet
            log.info("tile %s: block %d/%d classified", name, i + 1, len(blocks))
    Path(out_npz).parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(out_npz, classes=classes, r0=tile.r0, c0=tile.c0, water_cells=water)
    return water


def merge_kite_tiles(tile_files: Sequence[str | Path], hist_files: Sequence[str | Path], ortho_path: str | Path,
                     out_tif: str | Path, params: ObiaParams) -> ThresholdResult:
    """Write the bare-soil map from the tiles' cores; returns the global threshold (with ``water_cells``).

    Parameters
    ----------
    tile_files : sequence of path
        Every tile's class file (:func:`kite_map_tile`).
    hist_files : sequence of path
        Every tile's histogram file (:func:`kite_histogram_tile`).
    ortho_path : path
        RGB orthophoto; its grid is the map's.
    out_tif : path
        The bare-soil GeoTIFF (0 vegetated, 1 bare, 255 no data).
    params : ObiaParams
        Method parameters.

    Returns
    -------
    ThresholdResult
        The global threshold, with ``water_cells`` (cells left unclassified as open water).

    Raises
    ------
    InputError
        Tiles that do not cover the orthophoto grid exactly once.
    """
    from kitegully.io.raster import grid_of

    thr = merged_threshold(hist_files, params)
    with rasterio.open(ortho_path) as src:
        grid = grid_of(src, ortho_path)
    seen = np.zeros((grid.height, grid.width), bool)
    water = 0
    Path(out_tif).parent.mkdir(parents=True, exist_ok=True)
    with rasterio.open(out_tif, "w", **_profile(grid, 1, "uint8", NODATA, cog=True)) as dst:
        for f in tile_files:
            with np.load(f) as z:
                c, r0, c0 = z["classes"], int(z["r0"]), int(z["c0"])
                water += int(z["water_cells"])
            if seen[r0:r0 + c.shape[0], c0:c0 + c.shape[1]].any() or r0 + c.shape[0] > grid.height or c0 + c.shape[1] > grid.width:
                raise InputError(f"{f}: tile window overlaps another tile or leaves the orthophoto grid")
            seen[r0:r0 + c.shape[0], c0:c0 + c.shape[1]] = True
            dst.write(c, 1, window=Window(c0, r0, c.shape[1], c.shape[0]))
        dst.descriptions = ("bare_soil (0 vegetated, 1 bare, 255 no data)",)
    if not seen.all():
        raise InputError(f"{out_tif}: the kite-map tiles leave {int((~seen).sum())} orthophoto cells uncovered")
    thr.water_cells = water
    log.info("kite map merged from %d tiles", len(tile_files))
    return thr


def threshold_record(thr: ThresholdResult, path: str | Path) -> None:
    """Write the threshold record (``threshold.json``) as the untiled rule does."""
    with open(path, "w", encoding="utf-8") as fh:
        json.dump(thr.as_dict(), fh, indent=2)


def finish_kite_map(tile_files: Sequence[str | Path], hist_files: Sequence[str | Path], ortho_path: str | Path,
                    params: ObiaParams, out: dict, figure_max_px: float, attribution: str | None = None) -> ThresholdResult:
    """Rule ``obia_kite_merge``: the map (:func:`merge_kite_tiles`), its polygons, threshold record and figure.

    ``out`` holds the paths ``bare_soil``, ``polygons``, ``info`` and ``figure`` (the
    untiled rule's products, written the same way).

    Parameters
    ----------
    tile_files : sequence of path
        Every tile's class file (:func:`kite_map_tile`).
    hist_files : sequence of path
        Every tile's histogram file (:func:`kite_histogram_tile`).
    ortho_path : path
        RGB orthophoto.
    params : ObiaParams
        Method parameters.
    out : dict
        Product paths, keys as above.
    figure_max_px : float
        Largest side of the orthophoto in the figure (px).
    attribution : str or None
        Attribution line written below the figure.

    Returns
    -------
    ThresholdResult
        The global threshold (:func:`merge_kite_tiles`).
    """
    from kitegully.io.figures import save_figure
    from kitegully.io.raster import read_raster
    from kitegully.io.vectors import write_vector
    from kitegully.obia.classify import eroded_polygons
    from kitegully.obia.stage import kite_map_figure

    thr = merge_kite_tiles(tile_files, hist_files, ortho_path, out["bare_soil"], params)
    classes, grid = read_raster(out["bare_soil"])
    polygons = eroded_polygons(classes, grid.transform, grid.crs)
    write_vector(polygons, out["polygons"])
    threshold_record(thr, out["info"])
    bare = classes == 1
    log.info("bare soil: %.1f m² in %d polygons (%.2f %% of the mapped cells)", float(bare.sum() * grid.cell ** 2),
             len(polygons), 100.0 * bare.sum() / max(int((classes != NODATA).sum()), 1))
    fig = kite_map_figure(str(ortho_path), classes, grid, thr, figure_max_px, params.index)
    save_figure(fig, out["figure"], attribution=attribution)
    return thr
