"""Least-cost drainage directions: depressions breached along their lowest route (after Metz et al. 2011).

A priority-flood fill (:mod:`kitegully.terrain.fill`) raises every depression to its spill
level, and the flat it leaves is crossed by a geometric rule (flat resolution or an ε
gradient): a path that enters a filled reach of a gully is routed by the flat's shape, not by
the channel floor under it. GRASS ``r.watershed`` instead routes flow by a least-cost search
(Metz, Mitasova & Harmon 2011): cells are visited from the outlets inwards in order of their
**own** elevation (not raised), and each cell drains to a neighbour visited before it. Inside a
depression the search enters through the same spill cell as the fill (the depression's lowest
rim cell is reached first) and then descends through the depression's lowest cells, so the
route from the depression's floor back to the spill follows low ground: the channel, where
the depression is a channel dammed by a DSM artefact (a tree crown, a mismatch) or by a real
obstacle. Outside depressions the result is a steepest descent.

Rule of this implementation ([I]): when a cell is visited, it drains to the neighbour of
steepest descent (drop / distance, as :func:`kitegully.terrain.flow.d8_directions`) among
the neighbours already visited; where none of them is lower (the cell lies in a depression or
on a flat), to the lowest of them. Each cell drains to one visited earlier, so the directions
form a forest rooted at the outlets: no loops, every valid cell reaches an outlet.

Direction codes are those of :mod:`kitegully.terrain.flow` (0-7, 255 = outlet or nodata).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from kitegully.terrain.fill import _qpop, _qpush
from kitegully.terrain.flow import D8_OFFSETS, _INV_DIST, _is_outlet


@njit(cache=True, nogil=True)
def _least_cost(z, offs, inv):
    h, w = z.shape
    flat = z.ravel()
    n = h * w
    dirs = np.full(n, 255, dtype=np.uint8)
    state = np.zeros(n, dtype=np.uint8)  # 0 unseen, 1 queued, 2 visited
    heap = np.empty((max(1024, 4 * (h + w)), 2), dtype=np.float64)
    m = 0
    for r in range(h):
        for c in range(w):
            i = r * w + c
            if flat[i] == flat[i] and _is_outlet(flat, h, w, r, c, offs):
                heap, m = _qpush(heap, m, flat[i], i)
                state[i] = 1
    n_uphill = 0
    while m > 0:
        i, m = _qpop(heap, m)
        state[i] = 2
        r = i // w
        c = i - r * w
        zc = flat[i]
        outlet = _is_outlet(flat, h, w, r, c, offs)
        best, best_s = -1, 0.0
        low, low_z = -1, np.inf
        for k in range(8):
            rr = r + offs[k, 0]
            cc = c + offs[k, 1]
            if rr < 0 or cc < 0 or rr >= h or cc >= w:
                continue
            j = rr * w + cc
            zj = flat[j]
            if not (zj == zj):
                continue
            if state[j] == 2:
                if not outlet:
                    s = (zc - zj) * inv[k]
                    if s > best_s:
                        best_s, best = s, k
                    if zj < low_z:
                        low_z, low = zj, k
            elif state[j] == 0:
                heap, m = _qpush(heap, m, zj, j)
                state[j] = 1
        if not outlet:
            if best >= 0:
                dirs[i] = best
            else:
                dirs[i] = low
                n_uphill += 1
    return dirs, n_uphill


def least_cost_directions(z: np.ndarray) -> tuple[np.ndarray, int]:
    """D8 drainage directions of an unfilled DEM by least-cost search (depressions breached, not filled).

    Parameters
    ----------
    z : ndarray (H, W)
        DEM (m), NaN nodata; depressions need not be filled.

    Returns
    -------
    dirs : ndarray (H, W) uint8
        Direction codes 0-7 of :data:`kitegully.terrain.flow.D8_OFFSETS`; 255 for nodata
        and outlets (grid edge or next to nodata: they drain off the DEM). Every other valid
        cell has a direction, and following the directions from any cell reaches an outlet.
    n_uphill : int
        Cells that drain to a neighbour not lower than themselves: the breached routes out of
        depressions and the cells of flats.

    Notes
    -----
    O(n log q) time for n cells and a search front of q cells (q ≪ n on terrain: the front is
    a contour line); memory 2 bytes per cell plus 16 bytes per front cell.
    """
    a = np.asarray(z)
    a = np.ascontiguousarray(a, dtype=a.dtype if a.dtype in (np.float32, np.float64) else np.float64)  # no float32 copy
    if a.ndim != 2:
        raise ValueError("z must be a 2-D array")
    dirs, n_uphill = _least_cost(a, D8_OFFSETS, _INV_DIST)
    return dirs.reshape(a.shape), int(n_uphill)
