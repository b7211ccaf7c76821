"""True orthophoto: every cell takes its colour from the image that sees it best.

For each orthophoto cell the surface point comes from the DSM (holes filled with the
nearest valid elevation); among the images whose frame contains it and whose line of
sight is not blocked by the DSM, the one with the smallest off-nadir angle wins, and its
colour is resampled bilinearly from the pyramid level closest to the orthophoto cell.
Views are tried in order of that angle, so usually only one line of sight is marched.
"""

from __future__ import annotations

import logging

import cv2
import numpy as np

from numba.typed import List

from kitegully.dense.kernels import best_view_ortho
from kitegully.dense.matching import view_levels, visible_views
from kitegully.dense.views import PyramidCache, ViewSet
from kitegully.io.raster import GridSpec
from kitegully.terrain.holes import fill_nearest

log = logging.getLogger(__name__)


def ortho_block(upsample: int, tile_cells: int) -> int:
    """Side (DSM cells) of the blocks :func:`orthophoto` renders one at a time.

    Each block picks its candidate views and their pyramid levels from its own extent and
    median elevation, so a tile job that must reproduce the untiled orthophoto renders whole
    blocks of this side, starting at multiples of it (:mod:`kitegully.dense.ortho_tiles`).
    """
    return max(1, int(tile_cells) // int(upsample))


def fill_dsm(dsm: np.ndarray) -> np.ndarray:
    """The DSM (float64) with holes filled by the nearest valid elevation (any distance).

    Raises ``ValueError`` when no cell is valid. O(cells) time and memory.
    """
    filled = fill_nearest(np.asarray(dsm).astype(np.float64))
    if not np.isfinite(filled).any():
        raise ValueError("orthophoto: the DSM has no valid cell")
    return filled


def finest_level(views: ViewSet, zloc: np.ndarray, ocell: float) -> int:
    """Finest pyramid level any view needs: from the whole filled DSM's median (views' local frame).

    Parameters
    ----------
    views : ViewSet
        The oriented images (all of them are considered).
    zloc : ndarray (H, W)
        Filled DSM in the views' local frame (m).
    ocell : float
        Orthophoto cell size (m).

    Returns
    -------
    int
        The lowest pyramid level of :func:`kitegully.dense.matching.view_levels` over all views.
    """
    return int(view_levels(views, list(range(len(views.images))), float(np.median(zloc)), ocell).min())


def render_window(views: ViewSet, zloc: np.ndarray, zorigin: tuple[int, int], grid: GridSpec, rows: tuple[int, int],
                  cols: tuple[int, int], cache: PyramidCache, finest: int, upsample: int, block: int, overlap_m: float,
                  occlusion_tolerance_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Render the orthophoto cells of DSM rows ``rows`` and columns ``cols`` block by block.

    Parameters
    ----------
    zloc : (h, w) float64
        Filled DSM in the views' local frame over rows ``zorigin[0]..`` and columns
        ``zorigin[1]..`` of ``grid``; it must hold every block's occlusion margin
        (``overlap_m``, clipped to the grid).
    rows, cols : (start, stop)
        The window on ``grid``; starts are multiples of ``block`` (:func:`ortho_block`).
    cache, finest
        Pyramid cache with ``min_level=finest`` (:func:`finest_level`).

    Returns
    -------
    image : (B, h*upsample, w*upsample) uint8 (0 = nodata), source : int16 (−1 = none).
    """
    og = grid.refined(upsample)
    ocell = og.cell
    nb = cache.level(0, finest, colour=True).shape[2]
    (r_lo, r_hi), (c_lo, c_hi) = rows, cols
    za, zc = zorigin
    out = np.zeros((nb, (r_hi - r_lo) * upsample, (c_hi - c_lo) * upsample), np.uint8)
    source = np.full(out.shape[1:], -1, np.int16)
    # the DSM grid and the orthophoto grid in the views' local frame
    dsm_local = grid.shifted(-views.offset[0], -views.offset[1])
    ortho_local = og.shifted(-views.offset[0], -views.offset[1])
    marg = int(np.ceil(overlap_m / grid.cell))
    T = block
    for r0 in range(r_lo, r_hi, T):
        for c0 in range(c_lo, c_hi, T):
            h, w = min(T, grid.height - r0), min(T, grid.width - c0)
            # DSM window with margin for the occlusion test
            ra, rb = max(0, r0 - marg), min(grid.height, r0 + h + marg)
            ca, cb = max(0, c0 - marg), min(grid.width, c0 + w + marg)
            if ra < za or ca < zc or rb - za > zloc.shape[0] or cb - zc > zloc.shape[1]:
                raise ValueError(f"orthophoto: the DSM window misses the margin of block ({r0}, {c0})")
            zwin = np.ascontiguousarray(zloc[ra - za:rb - za, ca - zc:cb - zc])
            zt = zloc[r0 - za:r0 - za + h, c0 - zc:c0 - zc + w].astype(np.float32)
            zo = cv2.resize(zt, (w * upsample, h * upsample), interpolation=cv2.INTER_LINEAR).astype(np.float64) \
                if upsample > 1 else zt.astype(np.float64)
            xs, ys = ortho_local.cell_centres(r0 * upsample, c0 * upsample, h * upsample, w * upsample)
            win = dsm_local.window(ra, ca, rb - ra, cb - ca)
            zr = (float(zwin.min()), float(zwin.max()))
            idx = visible_views(views, (xs[0], xs[-1]), (ys[-1], ys[0]), zr)
            levels = view_levels(views, idx, float(np.median(zo)), ocell)
            imgs = List()
            for i, s in zip(idx, levels):
                imgs.append(cache.level(i, int(s), colour=True))
            vv = [views.images[i] for i in idx]
            tile_out = np.empty((nb,) + zo.shape, np.float32)
            tile_k = np.empty(zo.shape, np.int64)
            if idx:
                best_view_ortho(
                    imgs, np.ascontiguousarray([v.R for v in vv]), np.ascontiguousarray([v.C for v in vv]),
                    np.ascontiguousarray([v.params() for v in vv]), levels.astype(np.int64),
                    np.array([v.width for v in vv], np.int64), np.array([v.height for v in vv], np.int64),
                    xs, ys, zo, zwin, win.x0, win.y0, grid.cell, zr[1], grid.cell,
                    occlusion_tolerance_m, tile_out, tile_k)
            else:
                tile_k[:] = -1
            tile_src = np.where(tile_k >= 0, np.asarray(idx + [-1], np.int64)[tile_k], -1).astype(np.int16)
            sl = (slice((r0 - r_lo) * upsample, (r0 - r_lo + h) * upsample),
                  slice((c0 - c_lo) * upsample, (c0 - c_lo + w) * upsample))
            valid = tile_src >= 0
            out[(slice(None),) + sl] = np.where(valid, np.clip(np.rint(tile_out), 1, 255), 0).astype(np.uint8)
            source[sl] = tile_src
    return out, source


def orthophoto(views: ViewSet, dsm: np.ndarray, grid: GridSpec, upsample: int = 1, tile_cells: int = 512,
               overlap_m: float = 20.0, occlusion_tolerance_m: float = 0.3, max_cached_images: int = 16,
               arrays: list[np.ndarray] | None = None) -> tuple[np.ndarray, GridSpec, np.ndarray]:
    """Mosaic a true orthophoto on the DSM grid refined ``upsample`` times.

    Parameters
    ----------
    dsm, grid
        Surface (site elevations, NaN holes) and its grid in the site CRS.
    overlap_m
        DSM margin around each tile used for the occlusion test (m).
    occlusion_tolerance_m
        A line of sight is blocked where the DSM rises above it by more than this.

    Returns
    -------
    image : (B, H, W) uint8, 0 = nodata (valid values are clipped to 1–255)
    ortho_grid : the orthophoto grid
    source : (H, W) int16 index of the chosen image, −1 where none

    Cost: O(cells · V · (1 + ray march length / cell)). Tiled sites render the same blocks
    as tile jobs (:mod:`kitegully.dense.ortho_tiles`).
    """
    og = grid.refined(upsample)
    zloc = fill_dsm(dsm) - views.offset[2]
    finest = finest_level(views, zloc, og.cell)
    cache = PyramidCache(views, max_cached_images, arrays, min_level=finest)
    out, source = render_window(views, zloc, (0, 0), grid, (0, grid.height), (0, grid.width), cache, finest, upsample,
                                ortho_block(upsample, tile_cells), overlap_m, occlusion_tolerance_m)
    log.info("orthophoto: %d x %d cells at %.3f m, %.1f%% filled", og.width, og.height, og.cell, 100 * (source >= 0).mean())
    return out, og, source
