"""One-cell-wide skeletons as polylines and longest paths (8-connected pixel graphs)."""

from __future__ import annotations

import numpy as np
import scipy.ndimage as ndi
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components, dijkstra

_OFFS = [(-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1)]


def _graph(skel: np.ndarray) -> tuple[np.ndarray, np.ndarray, sp.csr_matrix]:
    """Pixels (rows, cols) and the symmetric weighted adjacency (1 or √2 cells)."""
    rr, cc = np.nonzero(skel)
    n = rr.size
    index = np.full(skel.shape, -1, dtype=np.int64)
    index[rr, cc] = np.arange(n)
    h, w = skel.shape
    src, dst, wt = [], [], []
    for dr, dc in _OFFS:
        r2, c2 = rr + dr, cc + dc
        ok = (r2 >= 0) & (r2 < h) & (c2 >= 0) & (c2 < w)
        j = np.full(n, -1)
        j[ok] = index[r2[ok], c2[ok]]
        ok = j >= 0
        src.append(np.nonzero(ok)[0])
        dst.append(j[ok])
        wt.append(np.full(ok.sum(), np.hypot(dr, dc)))
    g = sp.csr_matrix((np.concatenate(wt), (np.concatenate(src), np.concatenate(dst))), shape=(n, n))
    return rr, cc, g


def _drop_diagonal_shortcuts(g: sp.csr_matrix) -> sp.csr_matrix:
    """Remove diagonal edges that close a triangle with two orthogonal edges (staircases)."""
    g = g.tocoo()
    diag = g.data > 1.5
    orth = sp.csr_matrix((np.ones((~diag).sum()), (g.row[~diag], g.col[~diag])), shape=g.shape)
    two = orth @ orth  # paths of two orthogonal steps
    keep = ~diag | (np.asarray(two[g.row, g.col]).ravel() == 0)
    return sp.csr_matrix((g.data[keep], (g.row[keep], g.col[keep])), shape=g.shape)


def skeleton_paths(skel: np.ndarray, min_cells: int = 2) -> list[tuple[np.ndarray, np.ndarray]]:
    """Split a skeleton into polylines between end points and junctions.

    Parameters
    ----------
    skel : ndarray bool
        One-cell-wide skeleton.
    min_cells : int
        Paths with fewer pixels are dropped.

    Returns
    -------
    list of (rows, cols) int arrays, one per path, pixels in order along the path.

    Notes
    -----
    O(n) in the skeleton pixels n (plus a sparse product). Closed loops without a node
    are opened at an arbitrary pixel.
    """
    rr, cc, g = _graph(skel)
    n = rr.size
    if n == 0:
        return []
    g = _drop_diagonal_shortcuts(g).tocsr()
    deg = np.diff(g.indptr)
    nbrs = [g.indices[g.indptr[i]:g.indptr[i + 1]] for i in range(n)]
    node = deg != 2
    used_edge: set[tuple[int, int]] = set()
    seen = np.zeros(n, bool)
    paths = []

    def walk(start: int, nxt: int) -> list[int]:
        path = [start, nxt]
        used_edge.add((min(start, nxt), max(start, nxt)))
        prev, cur = start, nxt
        while not node[cur]:
            cand = [j for j in nbrs[cur] if j != prev and (min(cur, j), max(cur, j)) not in used_edge]
            if not cand:
                break
            prev, cur = cur, cand[0]
            used_edge.add((min(prev, cur), max(prev, cur)))
            path.append(cur)
            if cur == start:
                break
        return path

    for i in np.nonzero(node)[0]:
        seen[i] = True
        for j in nbrs[i]:
            if (min(i, j), max(i, j)) in used_edge:
                continue
            p = walk(i, j)
            seen[p] = True
            paths.append(p)
    # loops with no node
    for i in range(n):
        if seen[i] or deg[i] == 0:
            continue
        p = walk(i, nbrs[i][0])
        seen[p] = True
        paths.append(p)
    return [(rr[p], cc[p]) for p in map(np.asarray, paths) if len(p) >= min_cells]


def longest_path(mask_skel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Longest geodesic path through the largest component of a skeleton (pruned medial axis).

    Two Dijkstra sweeps (exact on a tree, a good approximation with loops). Returns the
    path pixels (rows, cols) in order; empty arrays for an empty skeleton.
    """
    rr, cc, g = _graph(mask_skel)
    if rr.size == 0:
        return rr, cc
    if rr.size == 1:
        return rr, cc
    ncomp, lab = connected_components(g, directed=False)
    if ncomp > 1:
        big = np.argmax(np.bincount(lab))
        keep = np.nonzero(lab == big)[0]
        g = g[keep][:, keep]
        rr, cc = rr[keep], cc[keep]
    d0 = dijkstra(g, directed=False, indices=0)
    u = int(np.argmax(np.where(np.isfinite(d0), d0, -1)))
    du, pred = dijkstra(g, directed=False, indices=u, return_predecessors=True)
    v = int(np.argmax(np.where(np.isfinite(du), du, -1)))
    path = [v]
    while path[-1] != u:
        path.append(int(pred[path[-1]]))
    path = np.asarray(path[::-1])
    return rr[path], cc[path]


def remove_short_components(mask: np.ndarray, min_cells: int) -> np.ndarray:
    """Drop 8-connected components with fewer than ``min_cells`` cells."""
    lab, n = ndi.label(mask, structure=np.ones((3, 3), bool))
    if n == 0:
        return mask.copy()
    size = np.bincount(lab.ravel())
    keep = size >= min_cells
    keep[0] = False
    return keep[lab]
