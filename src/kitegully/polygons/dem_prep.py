"""DEM preparation (Höfle et al. 2013 sect. 3.2): minimum z per cell, moving-plane gap fill."""

from __future__ import annotations

import logging

import numpy as np
import scipy.ndimage as ndi
from numba import njit
from scipy.spatial import cKDTree

from kitegully import InputError
from kitegully.io.raster import GridSpec

log = logging.getLogger(__name__)


@njit(cache=True)
def _block_min(z, r_idx, c_idx, out):
    h, w = z.shape
    for r in range(h):
        rr = r_idx[r]
        if rr < 0:
            continue
        for c in range(w):
            cc = c_idx[c]
            v = z[r, c]
            if cc < 0 or not np.isfinite(v):
                continue
            o = out[rr, cc]
            if not (o <= v):  # NaN or larger
                out[rr, cc] = v


def min_z_resample(z: np.ndarray, grid: GridSpec, cell: float) -> tuple[np.ndarray, GridSpec]:
    """Minimum elevation of the source cells whose centres fall in each target cell.

    Parameters
    ----------
    z : ndarray (H, W)
        Source elevations (m), NaN nodata.
    grid : GridSpec
        Source grid.
    cell : float
        Target cell size (m); the target grid has the same origin and covers the source
        extent rounded down to whole target cells.

    Returns
    -------
    out : ndarray float32
        Minimum z per target cell (NaN where no source cell centre falls).
    tgrid : GridSpec
        Target grid.

    Notes
    -----
    The minimum keeps the lowest return of a cell, the bare ground between plants where
    there is one (the paper's minimum-height raster). O(H·W).
    """
    if cell < grid.cell * (1 - 1e-9):
        raise InputError(f"polygons.cell_m: {cell} m is finer than the input DEM cell {grid.cell} m; resampling only coarsens")
    tgrid = grid.resampled(cell)
    xs, ys = grid.cell_centres()
    c_idx = np.floor((xs - tgrid.x0) / cell).astype(np.int64)
    r_idx = np.floor((tgrid.y0 - ys) / cell).astype(np.int64)
    c_idx[(c_idx < 0) | (c_idx >= tgrid.width)] = -1
    r_idx[(r_idx < 0) | (r_idx >= tgrid.height)] = -1
    out = np.full((tgrid.height, tgrid.width), np.nan, dtype=np.float64)
    _block_min(np.ascontiguousarray(z, dtype=np.float64), r_idx, c_idx, out)
    return out.astype(np.float32), tgrid


def fill_moving_planes(z: np.ndarray, cell: float, neighbours: int = 10, radius_m: float = 10.0) -> tuple[np.ndarray, int]:
    """Fill empty cells only, each with the best-fit plane through its nearest valid cells.

    Parameters
    ----------
    z : ndarray (H, W)
        Elevations (m), NaN = empty.
    cell : float
        Cell size (m).
    neighbours : int
        Number of nearest valid cells of the plane fit (paper: 10 laser points).
    radius_m : float
        Search radius (m) (paper: 10 m). Empty cells with fewer than 3 valid cells within
        it stay empty.

    Returns
    -------
    filled : ndarray float32
        ``z`` with the fillable empty cells filled; valid cells unchanged.
    n_filled : int
        Number of cells filled.

    Notes
    -----
    Vectorised: one k-d tree over the valid cells near gaps, one batched 3 × 3 normal
    equation solve. O(m log n) for m empty and n valid cells within the radius of a gap.
    """
    z = np.asarray(z, dtype=np.float32)
    empty = ~np.isfinite(z)
    if not empty.any():
        return z.copy(), 0
    valid = ~empty
    if valid.sum() < 3:
        raise InputError("polygons: the DEM has fewer than 3 cells with data")
    rad = int(np.ceil(radius_m / cell))
    near_gap = ndi.binary_dilation(empty, structure=np.ones((3, 3), bool), iterations=rad) & valid
    vr, vc = np.nonzero(near_gap)
    er, ec = np.nonzero(empty)
    pts = np.column_stack([vc, -vr]).astype(np.float64) * cell
    tree = cKDTree(pts)
    q = np.column_stack([ec, -er]).astype(np.float64) * cell
    k = min(neighbours, len(pts))
    dist, idx = tree.query(q, k=k, distance_upper_bound=radius_m)
    dist = dist.reshape(len(q), k)
    idx = idx.reshape(len(q), k)
    ok = np.isfinite(dist)
    nok = ok.sum(axis=1)
    fit = nok >= 3
    out = z.copy()
    if fit.any():
        okf = ok[fit]
        idf = np.where(okf, idx[fit], 0)
        dx = (pts[idf, 0] - q[fit, 0:1]) * okf
        dy = (pts[idf, 1] - q[fit, 1:2]) * okf
        zz = z[vr[idf], vc[idf]].astype(np.float64) * okf
        w = okf.astype(np.float64)
        # normal equations of z = p0 + p1 dx + p2 dy, centred on the empty cell
        A = np.empty((fit.sum(), 3, 3))
        A[:, 0, 0] = w.sum(1)
        A[:, 0, 1] = A[:, 1, 0] = dx.sum(1)
        A[:, 0, 2] = A[:, 2, 0] = dy.sum(1)
        A[:, 1, 1] = (dx * dx).sum(1)
        A[:, 1, 2] = A[:, 2, 1] = (dx * dy).sum(1)
        A[:, 2, 2] = (dy * dy).sum(1)
        b = np.stack([zz.sum(1), (zz * dx).sum(1), (zz * dy).sum(1)], axis=1)
        # tiny ridge on the slope terms: collinear neighbours give no slope across their line
        A[:, 1, 1] += 1e-9
        A[:, 2, 2] += 1e-9
        p0 = np.linalg.solve(A, b[..., None])[:, 0, 0]
        out[er[fit], ec[fit]] = p0.astype(np.float32)
    n = int(fit.sum())
    log.info("moving planes: %d of %d empty cells filled (%d left empty: < 3 cells within %.1f m)", n, len(q), len(q) - n, radius_m)
    return out, n


def open_water(valid: np.ndarray, cell: float, window_m: float, min_area_m2: float) -> np.ndarray:
    """Open water on a photogrammetric DSM: large regions where most of the surface found no match.

    Image matching fails on water (no texture of its own, glints that move between the
    photographs), so a reservoir shows as nodata sprinkled with a few matched cells at the
    water surface. A cell is *unmatched ground* when less than half of the cells in the
    ``window_m`` square around it hold data; 8-connected regions of such cells of at least
    ``min_area_m2`` are open water (smaller ones are matching gaps the moving planes fill).
    Stated limit: along the shore, a band up to half a window wide sees land in half its
    window and stays land (its water-surface matches are kept).

    Parameters
    ----------
    valid : ndarray bool (H, W)
        Cells of the input DSM with data.
    cell : float
        Its cell size (m).
    window_m : float
        Side of the square window (m).
    min_area_m2 : float
        Smallest region that is open water (m²).

    Returns
    -------
    ndarray bool (H, W)
        Open-water cells on the input grid. O(n): one box filter and one labelling.
    """
    size = max(1, int(round(window_m / cell)))
    share = ndi.uniform_filter(np.asarray(valid, dtype=np.float32), size=size, mode="nearest")
    sparse = share < 0.5
    if not sparse.any():
        return sparse
    labels, _n = ndi.label(sparse, structure=np.ones((3, 3), dtype=bool))
    area = np.bincount(labels.ravel()) * cell * cell
    big = area >= min_area_m2
    big[0] = False
    return big[labels]


def prepare_dem(z: np.ndarray, grid: GridSpec, cell: float, neighbours: int, radius_m: float,
                water_min_area_m2: float | None = None, water_window_m: float = 4.5) -> tuple[np.ndarray, GridSpec, dict]:
    """Minimum-z resampling to ``cell`` then moving-plane filling of the empty cells.

    With ``water_min_area_m2`` the open water of the input (:func:`open_water`, in a
    ``water_window_m`` window) is taken out first and stays empty: no surface, so no
    breaklines or pools there, and the fill drains into it as into the DEM's edge.

    Parameters
    ----------
    z : ndarray (H, W)
        Input DEM (m), NaN nodata.
    grid : GridSpec
        Its grid.
    cell : float
        The stage's cell (m), not finer than ``grid.cell``.
    neighbours, radius_m : int, float
        Moving planes: nearest valid cells per plane and search radius (m).
    water_min_area_m2 : float, optional
        Smallest open water (m²); None = no water test (a TLS or LiDAR DTM).
    water_window_m : float
        Window of the water test (m); the stage passes its curvature window.

    Returns
    -------
    dem : ndarray float32
        The prepared DEM, NaN where still empty (open water, cells beyond the planes' reach).
    grid : GridSpec
        The stage grid.
    counts : dict
        ``empty_cells``, ``filled_cells`` and ``water_cells`` (stage cells of open water).

    Notes
    -----
    O(n) in the input cells plus the moving planes' O(m log n).
    """
    if not np.isfinite(z).any():
        raise InputError("polygons: the input DEM is all nodata")
    water = None
    if water_min_area_m2:
        water = open_water(np.isfinite(z), grid.cell, water_window_m, water_min_area_m2)
        z = np.where(water, np.nan, z)
    zr, tgrid = min_z_resample(z, grid, cell)
    n_empty = int((~np.isfinite(zr)).sum())
    filled, n_filled = fill_moving_planes(zr, cell, neighbours, radius_m)
    n_water = 0
    if water is not None and water.any():
        # a stage cell is water where the input cell under its centre is
        cx, cy = tgrid.cell_centres()
        rows = np.clip(grid.index(np.full_like(cy, grid.x0), cy)[0], 0, grid.height - 1)
        cols = np.clip(grid.index(cx, np.full_like(cx, grid.y0))[1], 0, grid.width - 1)
        wt = water[np.ix_(rows, cols)]
        filled[wt] = np.nan
        n_water = int(wt.sum())
        log.info("open water: %d stage cells (%.0f m2) left empty", n_water, n_water * cell * cell)
    return filled, tgrid, {"empty_cells": n_empty, "filled_cells": n_filled, "water_cells": n_water}
