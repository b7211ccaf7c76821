"""Drainage directions over flat surfaces (Barnes, Lehman & Mulla 2014, after Garbrecht & Martz 1997).

A depression-filled DEM without an ε gradient (:func:`kitegully.terrain.fill.priority_flood_fill`
with ``epsilon=0``) holds flats: groups of equal-elevation cells, some of which have no
strictly lower D8 neighbour. Flow across a flat is routed by an integer mask that combines
two breadth-first gradients inside each flat:

* *towards lower terrain*: distance (in D8 steps) from the flat's low edges, i.e. the
  cells of the flat that already drain (outlets included);
* *away from higher terrain*: distance from the flat's high edges (undrained cells next to
  higher ground), reversed.

``mask = 2·towards + (H − away)`` where ``H`` is the flat's largest away-distance. Every
undrained flat cell has a neighbour of the same flat with a smaller mask, so every cell
drains; and because paths are pushed away from the flat's rim as well as towards its
outlet, they converge towards the middle of the flat instead of crossing it on parallel
straight lines as an ε-filled surface makes them do.

Direction codes are those of :mod:`kitegully.terrain.flow` (0-7, 255 = none).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from kitegully.terrain.flow import D8_OFFSETS, NO_FLOW, _INV_DIST, _is_outlet


@njit(cache=True)
def _append(buf, size, value):
    """Append ``value`` at ``buf[size]``, doubling the buffer when full; returns (buf, size + 1)."""
    if size == buf.size:
        bigger = np.empty(buf.size * 2, dtype=buf.dtype)
        bigger[:size] = buf[:size]
        buf = bigger
    buf[size] = value
    return buf, size + 1


@njit(cache=True, inline="always")
def _inner_neighbour(r, c, k, w, offs):
    """Flat index of the D8 neighbour ``k`` of a cell (r, c) known to be inside the grid
    (not an outlet, so not on the edge): no bounds test in the hot D8 pass."""
    return (r + offs[k, 0]) * w + c + offs[k, 1]


@njit(cache=True, inline="always")
def _neighbour(r, c, k, h, w, offs):
    """Flat index of the D8 neighbour ``k`` of cell (r, c), or -1 outside the grid.

    With :func:`_inner_neighbour`, the one neighbour step of every loop below
    (compiled inline)."""
    rr = r + offs[k, 0]
    cc = c + offs[k, 1]
    if rr < 0 or cc < 0 or rr >= h or cc >= w:
        return -1
    return rr * w + cc


@njit(cache=True)
def _flat_bfs(queue, qt, labels, dirs, outlet, seen, h, w, offs):
    """Breadth-first search from the ``qt`` seeds in ``queue`` over undrained cells of the
    seed's flat. Returns the queue (visit order), the BFS level of each visit (seeds = 1)
    and the number of visits; ``seen`` marks visited cells (seeds must be marked)."""
    level = np.empty(queue.size, dtype=np.int32)
    level[:qt] = 1
    qh = 0
    while qh < qt:
        i = queue[qh]
        lev = level[qh]
        qh += 1
        lab = labels[i]
        r = i // w
        c = i - r * w
        for k in range(8):
            j = _neighbour(r, c, k, h, w, offs)
            if j < 0 or labels[j] != lab or dirs[j] != 255 or outlet[j] == 1 or seen[j]:
                continue
            seen[j] = 1
            queue, qt2 = _append(queue, qt, j)
            if qt2 > level.size:
                bigger = np.empty(queue.size, dtype=np.int32)
                bigger[:qt] = level[:qt]
                level = bigger
            level[qt] = lev + 1
            qt = qt2
    return queue, level, qt


@njit(cache=True)
def _d8_pass(flat, h, w, offs, inv):
    """Phase 1: plain D8 (strictly lower steepest neighbour); outlets drain off the grid.

    Returns directions (255 = none), the outlet flags and the number of valid non-outlet
    cells without a direction."""
    n = h * w
    dirs = np.full(n, 255, dtype=np.uint8)
    outlet = np.zeros(n, dtype=np.uint8)
    n_noflow = 0
    for r in range(h):
        for c in range(w):
            i = r * w + c
            zc = flat[i]
            if not (zc == zc):
                continue
            if _is_outlet(flat, h, w, r, c, offs):
                outlet[i] = 1
                continue
            best = -1
            best_s = 0.0
            for k in range(8):
                j = _inner_neighbour(r, c, k, w, offs)  # a non-outlet cell is not on the edge
                s = (zc - flat[j]) * inv[k]
                if s > best_s:
                    best_s = s
                    best = k
            if best >= 0:
                dirs[i] = best
            else:
                n_noflow += 1
    return dirs, outlet, n_noflow


@njit(cache=True)
def _flat_edges(flat, h, w, offs, dirs, outlet):
    """Phase 2: edges of the flats. A drained cell (D8 direction or outlet) next to an
    undrained cell of the same elevation is a low edge; an undrained cell next to higher
    ground is a high edge. Returns (low, nlow, high, nhigh) as growable buffers."""
    low = np.empty(1024, dtype=np.int64)
    nlow = 0
    high = np.empty(1024, dtype=np.int64)
    nhigh = 0
    for r in range(h):
        for c in range(w):
            i = r * w + c
            zc = flat[i]
            if not (zc == zc):
                continue
            drained = outlet[i] == 1 or dirs[i] != 255
            for k in range(8):
                j = _neighbour(r, c, k, h, w, offs)
                if j < 0:
                    continue
                zn = flat[j]
                if not (zn == zn):
                    continue
                if drained:
                    if zn == zc and dirs[j] == 255 and outlet[j] == 0:
                        low, nlow = _append(low, nlow, i)
                        break
                elif zn > zc:
                    high, nhigh = _append(high, nhigh, i)
                    break
    return low, nlow, high, nhigh


@njit(cache=True)
def _label_flats(flat, h, w, offs, low, nlow):
    """Phase 3: label each flat (equal-elevation cells 8-connected to a low edge), 1..nlab.

    Returns the labels, their number and the queue buffer (reused by the later phases)."""
    n = h * w
    labels = np.zeros(n, dtype=np.int32)
    queue = np.empty(max(1024, nlow), dtype=np.int64)
    nlab = 0
    for t in range(nlow):
        s = low[t]
        if labels[s] != 0:
            continue
        nlab += 1
        target = flat[s]
        qh = 0
        queue[0] = s
        qt = 1
        labels[s] = nlab
        while qh < qt:
            i = queue[qh]
            qh += 1
            r = i // w
            c = i - r * w
            for k in range(8):
                j = _neighbour(r, c, k, h, w, offs)
                if j < 0 or labels[j] != 0 or flat[j] != target:
                    continue
                labels[j] = nlab
                queue, qt = _append(queue, qt, j)
    return labels, nlab, queue


@njit(cache=True)
def _flat_mask(queue, labels, nlab, dirs, outlet, low, nlow, high, nhigh, h, w, offs):
    """Phases 4-5: the combined flat mask ``2·towards + (H − away)`` (0 off the flats).

    4: away from higher terrain, BFS from the labelled high edges over undrained cells;
    5: towards lower terrain, BFS from the low edges, combined with the away gradient."""
    n = h * w
    mask = np.zeros(n, dtype=np.int32)
    height = np.zeros(nlab + 1, dtype=np.int32)
    seen = np.zeros(n, dtype=np.uint8)
    qt = 0
    for t in range(nhigh):
        i = high[t]
        if labels[i] != 0:
            seen[i] = 1
            queue, qt = _append(queue, qt, i)
    queue, level, qt = _flat_bfs(queue, qt, labels, dirs, outlet, seen, h, w, offs)
    for p in range(qt):
        i = queue[p]
        mask[i] = level[p]
        if height[labels[i]] < level[p]:
            height[labels[i]] = level[p]
    seen[:] = 0
    qt = 0
    for t in range(nlow):
        i = low[t]
        if not seen[i]:
            seen[i] = 1
            queue, qt = _append(queue, qt, i)
    queue, level, qt = _flat_bfs(queue, qt, labels, dirs, outlet, seen, h, w, offs)
    for p in range(qt):
        i = queue[p]
        if mask[i] > 0:
            mask[i] = height[labels[i]] - mask[i] + 2 * level[p]
        else:
            mask[i] = 2 * level[p]
    return mask


@njit(cache=True)
def _drain_flats(flat, h, w, offs, inv, dirs, outlet, labels, mask):
    """Phase 6: undrained flat cells flow to the same-flat neighbour with the steepest mask
    descent (``dirs`` updated in place). Returns (n_resolved, n_left)."""
    n_resolved = 0
    n_left = 0
    for i in range(h * w):
        if dirs[i] != 255 or outlet[i] == 1 or not (flat[i] == flat[i]):
            continue
        lab = labels[i]
        r = i // w
        c = i - r * w
        best = -1
        best_s = 0.0
        if lab != 0:
            mi = mask[i]
            for k in range(8):
                j = _inner_neighbour(r, c, k, w, offs)  # a labelled undrained cell is no outlet
                if labels[j] != lab:
                    continue
                s = (mi - mask[j]) * inv[k]
                if s > best_s:
                    best_s = s
                    best = k
        if best >= 0:
            dirs[i] = best
            n_resolved += 1
        else:
            n_left += 1
    return n_resolved, n_left


@njit(cache=True, nogil=True)
def _directions_with_flats(z, offs, inv):
    """D8 directions with flats resolved: the six phases above, in order."""
    h, w = z.shape
    flat = z.ravel()
    dirs, outlet, n_noflow = _d8_pass(flat, h, w, offs, inv)
    if n_noflow == 0:
        return dirs, 0, 0
    low, nlow, high, nhigh = _flat_edges(flat, h, w, offs, dirs, outlet)
    labels, nlab, queue = _label_flats(flat, h, w, offs, low, nlow)
    mask = _flat_mask(queue, labels, nlab, dirs, outlet, low, nlow, high, nhigh, h, w, offs)
    n_resolved, n_left = _drain_flats(flat, h, w, offs, inv, dirs, outlet, labels, mask)
    return dirs, n_resolved, n_left


def flow_directions(filled: np.ndarray, resolve_flats: bool = True) -> tuple[np.ndarray, int, int]:
    """D8 directions of a depression-filled DEM, with flats resolved (Barnes et al. 2014).

    Parameters
    ----------
    filled : ndarray (H, W)
        Depression-free DEM (e.g. :func:`priority_flood_fill` with ``epsilon=0``), NaN nodata.
    resolve_flats : bool
        Route undrained flat cells by the combined towards-lower / away-from-higher
        gradient; ``False`` leaves them without direction (255).

    Returns
    -------
    dirs : ndarray (H, W) uint8
        Direction codes 0-7 of :data:`kitegully.terrain.flow.D8_OFFSETS`; 255 for nodata,
        outlets (grid edge or next to nodata: they drain off the DEM) and cells left
        undrained.
    n_resolved : int
        Flat cells that got their direction from the flat mask.
    n_left : int
        Cells other than outlets that still have no direction: 0 on a depression-filled
        DEM; flats without any outlet (a closed depression that was not filled) stay.

    Notes
    -----
    Complexity O(n): two passes over the grid plus breadth-first searches over the flat
    cells only. Memory: one byte per cell for the directions plus, when flats exist, 9
    bytes per cell (labels, mask, flags) and the queues.
    """
    z = np.ascontiguousarray(filled, dtype=np.float64)
    if z.ndim != 2:
        raise ValueError("filled must be a 2-D array")
    if not resolve_flats:
        from kitegully.terrain.flow import d8_directions

        dirs = d8_directions(z)
        valid = np.isfinite(z)
        n_left = int(np.count_nonzero((dirs == NO_FLOW) & valid & ~_outlets(valid)))
        return dirs, 0, n_left
    dirs, n_resolved, n_left = _directions_with_flats(z, D8_OFFSETS, _INV_DIST)
    return dirs.reshape(z.shape), int(n_resolved), int(n_left)


def _outlets(valid: np.ndarray) -> np.ndarray:
    """Valid cells on the grid edge or next to nodata (D8)."""
    h, w = valid.shape
    pv = np.pad(valid, 1, constant_values=False)
    m = np.zeros_like(valid)
    for dr, dc in D8_OFFSETS:
        m |= ~pv[1 + dr : 1 + dr + h, 1 + dc : 1 + dc + w]
    return m & valid
