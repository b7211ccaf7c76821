"""Tiled dense matching of a whole site into a DSM grid, with bounded memory.

The grid is cut into square core tiles; each tile is matched on its core plus an overlap
margin (so windows and SGM paths near its edges see real neighbours) and only the core is
kept. Memory per tile is O((tile + 2·overlap)² · labels) and images are held in an LRU
pyramid cache, so the peak does not grow with the site.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import numpy as np

from kitegully import InputError
from kitegully.dense.matching import MatchParams, match_tile, view_levels, visible_views
from kitegully.dense.views import PyramidCache, ViewSet
from kitegully.io.raster import GridSpec

log = logging.getLogger(__name__)


@dataclass
class DenseResult:
    """DSM (site elevations, NaN nodata), NCC, usable and geometrically seeing image counts."""

    dsm: np.ndarray
    ncc: np.ndarray
    nviews: np.ndarray
    nseen: np.ndarray
    seconds: float
    tiles: int

    def coverage(self) -> float:
        """Share of the cells seen by ≥ 2 images that got a valid elevation."""
        seen = self.nseen >= 2
        return float(np.isfinite(self.dsm)[seen].mean()) if seen.any() else float("nan")


def tile_z_range(views: ViewSet, box: tuple[float, float, float, float], margin: float,
                 min_points: int = 10) -> tuple[float, float]:
    """Local elevation bounds for a tile from the tie points inside ``box`` (xmin, ymin,
    xmax, ymax, local); falls back to all tie points when the tile has fewer than
    ``min_points``. The 1st–99th percentile range is widened by ``margin``.

    Tie points rarely reach a tile's corners, and on a slope the terrain there lies beyond
    their elevation range by slope × distance (a 64 m tile on a 20 % valley side: ±6 m).
    So a plane is fitted to the tile's tie points and evaluated at the four corners; the
    range also covers those corner elevations plus the 1st–99th percentile residuals from
    the plane. The extrapolation is bounded by the elevation range of all tie points, so a
    badly conditioned fit cannot widen it beyond the site's relief.
    O(points).

    Parameters
    ----------
    views : ViewSet
        The oriented images and their tie points (local frame).
    box : (float, float, float, float)
        The tile's extent ``(xmin, ymin, xmax, ymax)`` (local, m).
    margin : float
        Margin added below and above the range (m).
    min_points : int
        Fewest tie points inside ``box`` for the tile's own range and plane fit.

    Returns
    -------
    lo, hi : float
        Lowest and highest elevation of the search (local, m).

    Raises
    ------
    InputError
        The model has no tie points.
    """
    P = views.sparse_points
    if len(P) == 0:
        raise InputError("dense matching: the model has no tie points to bound the elevation search")
    inside = (P[:, 0] >= box[0]) & (P[:, 0] <= box[2]) & (P[:, 1] >= box[1]) & (P[:, 1] <= box[3])

    def pct(z):
        return np.percentile(z, [1, 99]) if len(z) >= 20 else (z.min(), z.max())

    if inside.sum() < min_points:
        lo, hi = pct(P[:, 2])
        return float(lo - margin), float(hi + margin)
    glo, ghi = float(P[:, 2].min()), float(P[:, 2].max())
    Q = P[inside]
    lo, hi = pct(Q[:, 2])
    xc, yc = 0.5 * (box[0] + box[2]), 0.5 * (box[1] + box[3])
    A = np.column_stack([np.ones(len(Q)), Q[:, 0] - xc, Q[:, 1] - yc])
    coef, *_ = np.linalg.lstsq(A, Q[:, 2], rcond=None)
    rlo, rhi = pct(Q[:, 2] - A @ coef)
    hx, hy = 0.5 * (box[2] - box[0]), 0.5 * (box[3] - box[1])
    corners = coef[0] + np.array([-1, 1, -1, 1]) * coef[1] * hx + np.array([-1, -1, 1, 1]) * coef[2] * hy
    lo = min(lo, max(glo, corners.min() + rlo))
    hi = max(hi, min(ghi, corners.max() + rhi))
    return float(lo - margin), float(hi + margin)


def count_seen(views: ViewSet, idx: list[int], xs: np.ndarray, ys: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Number of images (among ``idx``) whose frame contains each ground point. O(cells·V).

    Parameters
    ----------
    views : ViewSet
        The oriented images.
    idx : list of int
        Indices in ``views.images`` of the images to test.
    xs, ys : ndarray (W,), (H,)
        Local coordinates of the cell centres (m).
    z : ndarray (H, W)
        Ground elevation of each cell (local, m).

    Returns
    -------
    ndarray (H, W) int16
        Number of images that have the point in front of the camera and inside the frame.
    """
    X = np.stack(np.broadcast_arrays(xs[None, :], ys[:, None], z), axis=-1)
    n = np.zeros(z.shape, np.int16)
    for i in idx:
        v = views.images[i]
        u, w, d = v.project(X)
        n += ((d > 0) & (u >= 0) & (w >= 0) & (u <= v.width - 1) & (w <= v.height - 1)).astype(np.int16)
    return n


def dense_surface(views: ViewSet, grid: GridSpec, params: MatchParams, tile_cells: int = 256,
                  overlap_cells: int = 16, max_cached_images: int = 32,
                  arrays: list[np.ndarray] | None = None) -> DenseResult:
    """Match all tiles of ``grid`` (site CRS) and assemble the DSM.

    ``arrays`` optionally gives the images in memory (same order as ``views.images``).
    Cost: O(tiles · per-tile cost of :func:`match_tile`); memory O(grid) for the outputs plus
    O(tile² · labels) working memory and the image cache.

    Parameters
    ----------
    views : ViewSet
        The oriented images and their tie points.
    grid : GridSpec
        The DSM grid (site CRS).
    params : MatchParams
        The matcher's parameters.
    tile_cells : int
        Core tile side (cells); rounded up to a multiple of ``2**(levels − 1)``.
    overlap_cells : int
        Margin matched on every side of a tile and then dropped (cells); rounded up to a multiple of
        ``2**(levels − 1)``.
    max_cached_images : int
        Image pyramids kept in the LRU cache.
    arrays : list of ndarray or None
        Images in memory; None = read the image files.

    Returns
    -------
    DenseResult
        DSM (site elevations, NaN nodata), NCC, usable and seeing image counts on ``grid``, matching time (s)
        and the number of tiles.
    """
    f = 2 ** (params.levels - 1)
    T = max(f, int(np.ceil(tile_cells / f)) * f)
    O = int(np.ceil(overlap_cells / f)) * f
    zmed = float(np.median(views.sparse_points[:, 2])) if len(views.sparse_points) else 0.0
    finest = int(view_levels(views, list(range(len(views.images))), zmed, grid.cell).min())
    cache = PyramidCache(views, max_cached_images, arrays, min_level=finest)
    dsm = np.full((grid.height, grid.width), np.nan, np.float32)
    ncc = np.full_like(dsm, np.nan)
    nviews = np.zeros(dsm.shape, np.int16)
    nseen = np.zeros(dsm.shape, np.int16)
    # cell centres in the views' local frame, with a margin of O cells around the grid and T beyond
    local = grid.shifted(-views.offset[0], -views.offset[1])
    xs_all, ys_all = local.cell_centres(-O, -O, grid.height + T + 2 * O, grid.width + T + 2 * O)
    t0 = time.perf_counter()
    warned = False
    starts = [(r, c) for r in range(0, grid.height, T) for c in range(0, grid.width, T)]
    for n, (r0, c0) in enumerate(starts):
        xs = xs_all[c0: c0 + T + 2 * O]
        ys = ys_all[r0: r0 + T + 2 * O]
        box = (xs[0], ys[-1], xs[-1], ys[0])
        zr = tile_z_range(views, box, params.z_margin_m)
        res = match_tile(views, cache, xs, ys, grid.cell, zr, params)
        if res.images > cache.max_images and not warned:
            # the passes read the tile's images in the same order: an LRU cache smaller than
            # that set misses on every read, so each pass re-reads and re-pyramids them all
            log.warning("dense matching: a tile is matched with %d images, more than the %d pyramids of "
                        "dense.max_cached_images: each of its passes re-reads them all (set dense.matching.max_views "
                        "to at most the cache size, or raise the cache)", res.images, cache.max_images)
            warned = True
        h = min(T, grid.height - r0)
        w = min(T, grid.width - c0)
        core = (slice(O, O + h), slice(O, O + w))
        dsm[r0:r0 + h, c0:c0 + w] = res.z[core] + views.offset[2]
        ncc[r0:r0 + h, c0:c0 + w] = res.ncc[core]
        nviews[r0:r0 + h, c0:c0 + w] = res.nviews[core]
        zc = res.z[core].astype(np.float64)
        if np.isfinite(zc).any():
            zc = np.where(np.isfinite(zc), zc, np.nanmedian(zc))
        else:
            zc = np.full(zc.shape, 0.5 * (zr[0] + zr[1]))
        idx = visible_views(views, (box[0], box[2]), (box[1], box[3]), zr)
        nseen[r0:r0 + h, c0:c0 + w] = count_seen(views, idx, xs[O:O + w], ys[O:O + h], zc)
        if (n + 1) % max(1, len(starts) // 10) == 0 or n + 1 == len(starts):
            log.info("dense matching: tile %d/%d done (%.1f s)", n + 1, len(starts), time.perf_counter() - t0)
    return DenseResult(dsm, ncc, nviews, nseen, time.perf_counter() - t0, len(starts))
