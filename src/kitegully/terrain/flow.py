"""D8 flow directions and steepest-descent tracing on a depression-free DEM.

Direction codes 0-7 index :data:`D8_OFFSETS` (row, column offsets: NW, N, NE, W, E, SW,
S, SE); 255 means no strictly lower neighbour. The steepest neighbour maximises
drop / distance (distance 1 or √2 cells); ties go to the first in code order.
"""

from __future__ import annotations

import numpy as np
from numba import njit

D8_OFFSETS = np.array([[-1, -1], [-1, 0], [-1, 1], [0, -1], [0, 1], [1, -1], [1, 0], [1, 1]], dtype=np.int64)
NO_FLOW = 255

#: End of a traced path: reached an outlet (grid edge or cell next to nodata).
END_OUTLET = 0
#: End of a traced path: joined a path traced before (confluence).
END_MERGE = 1
#: End of a traced path: no strictly lower neighbour (only with ε = 0 and flats left
#: unresolved, or NaN input).
END_PIT = 2
#: The head lies on a path traced before: empty path.
END_ON_NETWORK = 3

_INV_DIST = np.array([1 / np.sqrt(2), 1.0, 1 / np.sqrt(2), 1.0, 1.0, 1 / np.sqrt(2), 1.0, 1 / np.sqrt(2)])


@njit(cache=True)
def _steepest(flat, h, w, r, c, offs, inv):
    zc = flat[r * w + c]
    best = -1
    best_s = 0.0
    for k in range(8):
        rr = r + offs[k, 0]
        cc = c + offs[k, 1]
        if rr < 0 or cc < 0 or rr >= h or cc >= w:
            continue
        zn = flat[rr * w + cc]
        if not (zn == zn):
            continue
        s = (zc - zn) * inv[k]
        if s > best_s:
            best_s = s
            best = k
    return best


@njit(cache=True)
def _is_outlet(flat, h, w, r, c, offs):
    if r == 0 or c == 0 or r == h - 1 or c == w - 1:
        return True
    for k in range(8):
        z = flat[(r + offs[k, 0]) * w + c + offs[k, 1]]
        if not (z == z):
            return True
    return False


@njit(cache=True)
def _d8(z, offs, inv):
    h, w = z.shape
    flat = z.ravel()
    out = np.full(h * w, 255, dtype=np.uint8)
    for r in range(h):
        for c in range(w):
            if not (flat[r * w + c] == flat[r * w + c]):
                continue
            k = _steepest(flat, h, w, r, c, offs, inv)
            if k >= 0:
                out[r * w + c] = k
    return out.reshape(h, w)


def d8_directions(filled: np.ndarray) -> np.ndarray:
    """D8 steepest-descent direction code of every cell (uint8, 255 = none or nodata).

    Complexity O(n).
    """
    z = np.ascontiguousarray(filled, dtype=np.float64)
    return _d8(z, D8_OFFSETS, _INV_DIST)


@njit(cache=True)
def _trace(z, heads, offs, inv, dirs, use_dirs):
    h, w = z.shape
    flat = z.ravel()
    dflat = dirs.ravel()
    onnet = np.zeros(h * w, dtype=np.uint8)
    cap = 1024
    cells = np.empty(cap, dtype=np.int64)
    down = np.empty(cap, dtype=np.int64)
    n = 0
    starts = np.empty(heads.size + 1, dtype=np.int64)
    ends = np.empty(heads.size, dtype=np.int64)
    for p in range(heads.size):
        starts[p] = n
        i = heads[p]
        if onnet[i]:
            ends[p] = 3
            continue
        while True:
            if n == cap:
                cap *= 2
                nc = np.empty(cap, dtype=np.int64)
                nd = np.empty(cap, dtype=np.int64)
                nc[:n] = cells[:n]
                nd[:n] = down[:n]
                cells = nc
                down = nd
            onnet[i] = 1
            cells[n] = i
            r = i // w
            c = i - r * w
            if _is_outlet(flat, h, w, r, c, offs):
                down[n] = -1
                n += 1
                ends[p] = 0
                break
            if use_dirs:
                k = np.int64(dflat[i])
                if k == 255:
                    k = -1
            else:
                k = _steepest(flat, h, w, r, c, offs, inv)
            if k < 0:
                down[n] = -1
                n += 1
                ends[p] = 2
                break
            j = (r + offs[k, 0]) * w + c + offs[k, 1]
            down[n] = j
            n += 1
            if onnet[j]:
                ends[p] = 1
                break
            i = j
    starts[heads.size] = n
    return cells[:n], down[:n], starts, ends


def trace_paths(
    filled: np.ndarray, heads: np.ndarray, directions: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Follow D8 steepest descent from each head down to an outlet or an earlier path.

    Heads are traced in the given order. A path stops at an outlet (grid edge or a cell
    next to nodata), when it reaches a cell of a path traced before (confluence: the
    two paths merge), or, only possible with ε = 0, at a cell without lower neighbour.

    Parameters
    ----------
    filled : ndarray (H, W)
        Depression-free DEM (NaN nodata).
    heads : ndarray of int
        Flat (row-major) indices of the start cells.
    directions : ndarray (H, W) uint8, optional
        D8 direction codes to follow instead of the steepest descent on ``filled``
        (e.g. :func:`kitegully.terrain.flats.flow_directions`, flats resolved); 255 ends
        the path (a pit, :data:`END_PIT`, unless the cell is an outlet).

    Returns
    -------
    cells : ndarray int64
        Flat indices of all traced cells, path after path, each in downstream order.
    down : ndarray int64
        Flat index of the next cell downstream (-1 at an outlet or a pit).
    starts : ndarray int64 (k + 1)
        Path ``p`` is ``cells[starts[p]:starts[p + 1]]``.
    ends : ndarray int64 (k)
        How each path ended: :data:`END_OUTLET`, :data:`END_MERGE`, :data:`END_PIT`
        or :data:`END_ON_NETWORK`.

    Notes
    -----
    Complexity O(L) in the number of traced cells, plus one byte per grid cell.
    """
    z = np.ascontiguousarray(filled, dtype=np.float64)
    heads = np.asarray(heads, dtype=np.int64).ravel()
    if heads.size and (heads.min() < 0 or heads.max() >= z.size):
        raise ValueError("head index outside the grid")
    if directions is None:
        return _trace(z, heads, D8_OFFSETS, _INV_DIST, np.zeros((1, 1), dtype=np.uint8), False)
    directions = np.ascontiguousarray(directions, dtype=np.uint8)
    if directions.shape != z.shape:
        raise ValueError(f"directions shape {directions.shape} differs from the DEM's {z.shape}")
    return _trace(z, heads, D8_OFFSETS, _INV_DIST, directions, True)
