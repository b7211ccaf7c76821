"""Depression filling by priority flood with an epsilon gradient (Barnes et al. 2014).

Cells are processed from the outlets (grid edge and cells next to nodata) inwards in
order of their filled elevation. A cell reached from a processed neighbour ``c`` gets
``W = max(Z, W(c) + ε)``, so every cell ends strictly above the neighbour it was reached
from and therefore drains (strictly lower D8 neighbour) when ε > 0; with ε = 0 the result
is the classic minimal depression-filled surface (flats stay flat).

Cells raised into a depression go to a FIFO "pit" queue instead of the heap (Barnes'
improved variant). The next cell is whichever of the pit front and the heap top is lower,
so the processing order is exactly non-decreasing and the result is the unique minimal
surface W with W ≥ Z and ``W(c) ≥ min_neighbour W + ε`` for every inner cell.

Two speed-ups (issue 21) leave that surface unchanged bit for bit: a slope cell (higher
than its neighbour's final elevation + ε, so its own elevation is final) whose open
neighbours are all at least its elevation + ε is expanded at once instead of waiting in
the heap, and so are the slope cells found from it (after Zhou, Sun & Fu 2016; on a
4 M-cell synthetic catchment 1.6 M cells skip the heap); the heap is 4-ary with key and cell
stored side by side (one cache line per level). A traced cell's open neighbours are gathered
in one pass (session 9: 1.18x on the benchmark tile, same surface).
"""

from __future__ import annotations

import numpy as np
from numba import njit

_DR = np.array([-1, -1, -1, 0, 0, 1, 1, 1], dtype=np.int64)
_DC = np.array([-1, 0, 1, -1, 1, -1, 0, 1], dtype=np.int64)


@njit(cache=True)
def _heap_push(hidx, hkey, n, item, key):
    if n == hidx.size:
        bi = np.empty(hidx.size * 2, dtype=hidx.dtype)
        bk = np.empty(hidx.size * 2, dtype=hkey.dtype)
        bi[:n] = hidx[:n]
        bk[:n] = hkey[:n]
        hidx = bi
        hkey = bk
    # sift up with a hole: keys live next to the indices (no indirection, cache friendly)
    i = n
    while i > 0:
        p = (i - 1) >> 1
        if hkey[p] > key:
            hidx[i] = hidx[p]
            hkey[i] = hkey[p]
            i = p
        else:
            break
    hidx[i] = item
    hkey[i] = key
    return hidx, hkey, n + 1


@njit(cache=True)
def _heap_pop(hidx, hkey, n):
    top = hidx[0]
    n -= 1
    item = hidx[n]
    key = hkey[n]
    i = 0
    while True:
        l = 2 * i + 1
        if l >= n:
            break
        m = l
        if l + 1 < n and hkey[l + 1] < hkey[l]:
            m = l + 1
        if hkey[m] < key:
            hidx[i] = hidx[m]
            hkey[i] = hkey[m]
            i = m
        else:
            break
    if n > 0:
        hidx[i] = item
        hkey[i] = key
    return top, n


@njit(cache=True)
def _fifo_push(buf, head, size, item):
    if size == buf.size:
        bigger = np.empty(buf.size * 2, dtype=buf.dtype)
        for k in range(size):
            bigger[k] = buf[(head + k) % buf.size]
        buf = bigger
        head = 0
    buf[(head + size) % buf.size] = item
    return buf, head, size + 1


@njit(cache=True)
def _qpush(heap, n, key, item):
    """Push ``item`` (a cell index, exact as float64 below 2**53) with ``key`` on the 4-ary
    min-heap ``heap`` ((capacity, 2) float64 rows ``key, item``: a node's four children are
    64 contiguous bytes, so a level costs one cache line). Returns the heap (grown when
    full) and the new size."""
    if n == heap.shape[0]:
        bigger = np.empty((2 * n, 2), dtype=np.float64)
        bigger[:n] = heap[:n]
        heap = bigger
    i = n
    while i > 0:
        p = (i - 1) >> 2
        if heap[p, 0] > key:
            heap[i, 0] = heap[p, 0]
            heap[i, 1] = heap[p, 1]
            i = p
        else:
            break
    heap[i, 0] = key
    heap[i, 1] = item
    return heap, n + 1


@njit(cache=True)
def _qpop(heap, n):
    """Pop the item of least key from the 4-ary heap of :func:`_qpush`: (item, new size)."""
    top = np.int64(heap[0, 1])
    n -= 1
    key = heap[n, 0]
    item = heap[n, 1]
    i = 0
    while True:
        c = 4 * i + 1
        if c >= n:
            break
        m = c
        mk = heap[c, 0]
        e = min(c + 4, n)
        for cc in range(c + 1, e):
            if heap[cc, 0] < mk:
                mk = heap[cc, 0]
                m = cc
        if mk < key:
            heap[i, 0] = mk
            heap[i, 1] = heap[m, 1]
            i = m
        else:
            break
    if n > 0:
        heap[i, 0] = key
        heap[i, 1] = item
    return top, n


@njit(cache=True)
def _grow(buf, used):
    bigger = np.empty(buf.size * 2, dtype=buf.dtype)
    bigger[:used] = buf[:used]
    return bigger


@njit(cache=True, nogil=True)
def _priority_flood(w, valid, eps, dr, dc):
    h, wd = w.shape
    n = h * wd
    flat = w.ravel()
    vflat = valid.ravel()
    off = dr * wd + dc  # flat offsets of the 8 neighbours
    # 0 open, 1 closed (final elevation known), 3 closed seed on the grid edge (bounds checks)
    closed = np.zeros(n, dtype=np.uint8)
    heap = np.empty((max(1024, 2 * (h + wd)), 2), dtype=np.float64)
    nheap = 0
    pit = np.empty(1024, dtype=np.int64)  # FIFO of raised cells: [phead, ptail), reset when empty
    phead = 0
    ptail = 0
    trace = np.empty(1024, dtype=np.int64)  # stack of slope cells to expand at once
    ntrace = 0
    nb = np.empty(8, dtype=np.int64)
    nraised = 0
    # Seeds: valid cells on the grid edge or next to nodata (outlets). Every other valid
    # cell is inside the grid with 8 valid or closed neighbours: no bounds checks for it.
    for r in range(h):
        for c in range(wd):
            i = r * wd + c
            if not vflat[i]:
                closed[i] = 1
                continue
            edge = r == 0 or c == 0 or r == h - 1 or c == wd - 1
            seed = edge
            if not seed:
                for k in range(8):
                    if not vflat[i + off[k]]:
                        seed = True
                        break
            if seed:
                closed[i] = 3 if edge else 1
                heap, nheap = _qpush(heap, nheap, flat[i], i)
    while nheap > 0 or phead < ptail:
        if phead < ptail and (nheap == 0 or flat[pit[phead]] <= heap[0, 0]):
            i = pit[phead]
            phead += 1
            if phead == ptail:
                phead = 0
                ptail = 0
        else:
            i, nheap = _qpop(heap, nheap)
        target = flat[i] + eps
        on_edge = closed[i] == 3
        r = 0
        c = 0
        if on_edge:
            r = i // wd
            c = i - r * wd
        for k in range(8):
            if on_edge:
                rr = r + dr[k]
                cc = c + dc[k]
                if rr < 0 or cc < 0 or rr >= h or cc >= wd:
                    continue
            j = i + off[k]
            if closed[j]:
                continue
            closed[j] = 1
            if flat[j] <= target:
                if flat[j] < target:
                    nraised += 1
                flat[j] = target
                if ptail == pit.size:
                    if phead > 0:
                        pit[: ptail - phead] = pit[phead:ptail]
                        ptail -= phead
                        phead = 0
                    else:
                        pit = _grow(pit, ptail)
                pit[ptail] = j
                ptail += 1
                continue
            # j is on a slope: its final elevation is its own (it is higher than the final
            # elevation + eps of a neighbour). Expand it, and the slope cells found from it, at
            # once when none of their open neighbours is lower than them + eps: those
            # neighbours then keep their own elevation too, whatever the order (Zhou et al.
            # 2016's variant). A cell with a lower open neighbour waits in the heap.
            trace[0] = j
            ntrace = 1
            while ntrace > 0:
                ntrace -= 1
                s_ = trace[ntrace]
                ts = flat[s_] + eps
                # the open neighbours, gathered once: expanded if none is lower than s_ + eps
                nopen = 0
                lower = False
                for kk in range(8):
                    q = s_ + off[kk]
                    if closed[q] == 0:
                        if flat[q] < ts:
                            lower = True
                            break
                        nb[nopen] = q
                        nopen += 1
                if lower:
                    heap, nheap = _qpush(heap, nheap, flat[s_], s_)
                    continue
                if ntrace + nopen > trace.size:
                    trace = _grow(trace, ntrace)
                for kk in range(nopen):
                    q = nb[kk]
                    closed[q] = 1
                    trace[ntrace] = q
                    ntrace += 1
    return nraised


def priority_flood_fill(z: np.ndarray, epsilon: float = 1e-4) -> tuple[np.ndarray, int]:
    """Fill depressions so that every cell drains to the grid edge or to nodata.

    Parameters
    ----------
    z : ndarray (H, W)
        Elevations (m); NaN is nodata (outside the surveyed area; interpolate interior
        holes first with :func:`kitegully.terrain.holes.interpolate_holes`).
    epsilon : float
        Minimum rise per cell across filled areas (m). With ε > 0 every valid cell that
        is not an outlet has a strictly lower D8 neighbour. [I] 1e-4 m per cell.

    Returns
    -------
    filled : ndarray (H, W) float64
        The filled surface (NaN where ``z`` is NaN).
    n_raised : int
        Number of cells raised.

    Notes
    -----
    Complexity O(n log n) time (4-ary heap; cells inside depressions pass through an
    O(1) FIFO and traced slope cells through an O(1) stack), O(n) memory: the float64
    result, a byte per cell and the queues.
    """
    if epsilon < 0:
        raise ValueError(f"epsilon must be >= 0, got {epsilon}")
    w = np.array(z, dtype=np.float64, order="C", copy=True)
    if w.ndim != 2:
        raise ValueError("z must be a 2-D array")
    valid = np.isfinite(w)
    n = _priority_flood(w, valid, float(epsilon), _DR, _DC)
    return w, int(n)
