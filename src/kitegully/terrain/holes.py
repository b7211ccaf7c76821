"""Interior nodata holes of a DEM: find them and fill them by Laplace interpolation.

A hole is a 4-connected group of nodata cells that does not touch the grid edge; nodata
that reaches the edge is "outside" the surveyed area and stays nodata (it drains the DEM
in depression filling, like the grid edge).
"""

from __future__ import annotations

import numpy as np
import scipy.ndimage as ndi
import scipy.sparse as sp
import scipy.sparse.linalg as spla

_FOUR = ndi.generate_binary_structure(2, 1)


def fill_nearest(z: np.ndarray) -> np.ndarray:
    """NaN cells take the value of the nearest valid cell (Euclidean distance between centres).

    Ties go to the cell :func:`scipy.ndimage.distance_transform_edt` returns. An input
    without NaN, or with nothing but NaN, is returned as is (the same array object).
    Complexity O(n) for n cells.
    """
    bad = ~np.isfinite(z)
    if not bad.any() or bad.all():
        return z
    idx = ndi.distance_transform_edt(bad, return_distances=False, return_indices=True)
    return z[tuple(idx)]


def interior_holes(valid: np.ndarray) -> np.ndarray:
    """Boolean mask of nodata cells in 4-connected groups that do not touch the grid edge.

    Complexity O(n).
    """
    invalid = ~np.asarray(valid, dtype=bool)
    if not invalid.any():
        return invalid
    labels, n = ndi.label(invalid, structure=_FOUR)
    edge = np.unique(np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]]))
    outer = np.zeros(n + 1, dtype=bool)
    outer[edge] = True
    outer[0] = True
    return ~outer[labels]


def interior_holes_below(valid: np.ndarray, max_cells: int | None) -> np.ndarray:
    """Interior holes (see :func:`interior_holes`) of fewer than ``max_cells`` cells.

    ``max_cells=None`` keeps every interior hole. Complexity O(n).
    """
    holes = interior_holes(valid)
    if max_cells is None or not holes.any():
        return holes
    labels, _ = ndi.label(holes, structure=_FOUR)
    sizes = np.bincount(labels.ravel())
    small = sizes < max_cells
    small[0] = False
    return small[labels]


def interpolate_holes(z: np.ndarray, max_cells: int | None = None) -> tuple[np.ndarray, int]:
    """Fill interior NaN holes with the harmonic (Laplace) interpolation of their rim.

    Each hole cell takes the mean of its four neighbours; valid neighbours are fixed
    values. All holes are solved together as one sparse linear system.

    Parameters
    ----------
    z : ndarray (H, W)
        Elevations with NaN nodata.
    max_cells : int, optional
        Only holes of fewer cells are interpolated; larger ones stay NaN (e.g. open water,
        where photogrammetry finds no match: their rim then drains the DEM like its edge).
        ``None`` interpolates every interior hole.

    Returns
    -------
    filled : ndarray (H, W), same dtype as ``z``
        Copy of ``z`` with interior holes filled; NaN outside the surveyed area is kept.
    n_cells : int
        Number of interpolated cells.

    Notes
    -----
    Complexity: O(n) to find the holes plus a sparse direct solve on the m hole cells
    (about O(m^1.5) for compact holes).
    """
    z = np.asarray(z)
    holes = interior_holes_below(np.isfinite(z), max_cells)
    m = int(holes.sum())
    out = z.copy()
    if m == 0:
        return out, 0
    rows, cols = np.nonzero(holes)
    index = np.full(z.shape, -1, dtype=np.int64)
    index[rows, cols] = np.arange(m)
    ii, jj, vv = [np.arange(m)], [np.arange(m)], [np.full(m, 4.0)]
    rhs = np.zeros(m)
    for dr, dc in ((-1, 0), (1, 0), (0, -1), (0, 1)):
        # Interior holes never touch the edge, so neighbours are inside the grid.
        nr, nc = rows + dr, cols + dc
        nidx = index[nr, nc]
        is_hole = nidx >= 0
        ii.append(np.nonzero(is_hole)[0])
        jj.append(nidx[is_hole])
        vv.append(np.full(int(is_hole.sum()), -1.0))
        known = ~is_hole
        np.add.at(rhs, np.nonzero(known)[0], z[nr[known], nc[known]].astype(np.float64))
    a = sp.csr_matrix((np.concatenate(vv), (np.concatenate(ii), np.concatenate(jj))), shape=(m, m))
    sol = spla.spsolve(a.tocsc(), rhs)
    out[rows, cols] = sol.astype(z.dtype)
    return out, m
