"""One-cell-wide skeletons as polylines and longest paths (8-connected pixel graphs)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import scipy.ndimage as ndi
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components, dijkstra

if TYPE_CHECKING:
    import networkx as nx

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
    if g.nnz == 0:  # an isolated pixel: nothing to drop (and sparse fancy indexing with no index returns a sparse matrix)
        return g.tocsr()
    diag = g.data > 1.2  # √2 steps (orthogonal ones weigh 1; 1.5 matched none, so every junction was a triangle of nodes)
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


def _skeleton_graph(skel: np.ndarray):
    """Skeleton as a multigraph: nodes = end/junction pixels (row, col), edges carry their pixel paths."""
    import networkx as nx

    G = nx.MultiGraph()
    for rr, cc in skeleton_paths(skel, min_cells=2):
        a, b = (int(rr[0]), int(cc[0])), (int(rr[-1]), int(cc[-1]))
        if a == b:  # a closed loop: it encloses nothing after hole filling; keep it as a chain to itself
            continue
        seg = np.hypot(np.diff(rr), np.diff(cc)).sum()
        G.add_edge(a, b, rr=rr, cc=cc, length=float(seg))
    return G


def _chain_from_leaf(G, leaf):
    """Nodes and edge keys from a leaf through degree-2 nodes to the first other node."""
    nodes, keys = [leaf], []
    prev, cur = None, leaf
    while True:
        nxt = [(v, k) for _, v, k in G.edges(cur, keys=True) if not (v == prev and len(keys) and keys[-1][2] == k)]
        if not nxt:
            break
        v, k = nxt[0]
        keys.append((cur, v, k))
        nodes.append(v)
        prev, cur = cur, v
        if G.degree(v) != 2 or v == leaf:
            break
    return nodes, keys


def prune_network(G: nx.MultiGraph, radius: np.ndarray, min_extension: float) -> None:
    """Drop terminal branches that reach less than ``min_extension`` beyond their parent's edge (in place).

    A terminal branch (leaf to the next junction through degree-2 nodes) of length L that
    joins at a junction of inscribed radius r (the parent channel's half width there) is a
    tributary only if ``L − r ≥ min_extension``; otherwise it is the spur the thinning draws
    into a bump of the outline. Repeated until no branch is dropped (a junction left with two
    branches becomes part of a longer chain).

    Parameters
    ----------
    G : networkx.MultiGraph
        Skeleton graph: nodes are (row, col) end and junction pixels, edges carry their ``length`` (cells).
    radius : ndarray (H, W) float
        Inscribed radius per cell (cells).
    min_extension : float
        Least reach of a branch beyond its parent's edge (cells).
    """
    changed = True
    while changed:
        changed = False
        for leaf in [n for n in G.nodes if G.degree(n) == 1]:
            if leaf not in G or G.degree(leaf) != 1:
                continue
            nodes, keys = _chain_from_leaf(G, leaf)
            end = nodes[-1]
            if G.degree(end) < 3:  # the component is a single chain: nothing to prune
                continue
            L = sum(G.edges[k]["length"] for k in keys)
            if L - radius[end] < min_extension:
                G.remove_edges_from(keys)
                G.remove_nodes_from([n for n in nodes[:-1] if G.degree(n) == 0])
                changed = True


def _path_pixels(G, nodes) -> tuple[np.ndarray, np.ndarray]:
    rs, cs = [], []
    for a, b in zip(nodes[:-1], nodes[1:]):
        k = min(G[a][b], key=lambda k: G[a][b][k]["length"])
        d = G[a][b][k]
        rr, cc = d["rr"], d["cc"]
        if (int(rr[0]), int(cc[0])) != a:
            rr, cc = rr[::-1], cc[::-1]
        rs.append(rr if not rs else rr[1:])
        cs.append(cc if not cs else cc[1:])
    return np.concatenate(rs), np.concatenate(cs)


def branch_paths(skel: np.ndarray, radius: np.ndarray, min_extension: float) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """The pruned medial network of a skeleton as a main stem and its branches.

    Parameters
    ----------
    skel : ndarray bool
        One-cell-wide skeleton of one polygon.
    radius : ndarray float
        Inscribed radius (distance to the outline) per cell, in cells.
    min_extension : float
        Pruning length (cells) for :func:`prune_network`.

    Returns
    -------
    list of (rows, cols, trim)
        First the longest path of the largest component (the paper's pruned medial axis),
        then, repeatedly, the longest path into what is left, starting where it leaves the
        paths already taken; ``trim`` is the inscribed radius at that start (cells): the
        branch's first ``trim`` cells lie inside its parent channel.

    Notes
    -----
    O(n log n) in the skeleton pixels (Dijkstra sweeps on the node graph).
    """
    import networkx as nx

    G = _skeleton_graph(skel)
    if G.number_of_edges() == 0:
        rr, cc = longest_path(skel)
        return [(rr, cc, 0.0)] if rr.size >= 2 else []
    big = max(nx.connected_components(G), key=lambda c: sum(d["length"] for _, _, d in G.subgraph(c).edges(data=True)))
    G = nx.MultiGraph(G.subgraph(big))
    prune_network(G, radius, min_extension)
    W = nx.Graph()
    for a, b, d in G.edges(data=True):
        if not W.has_edge(a, b) or W[a][b]["length"] > d["length"]:
            W.add_edge(a, b, length=d["length"])
    # main stem: double sweep for the longest path (exact on a tree)
    n0 = next(iter(W.nodes))
    d0 = nx.single_source_dijkstra_path_length(W, n0, weight="length")
    u = max(d0, key=d0.get)
    du, pu = nx.single_source_dijkstra(W, u, weight="length")
    v = max(du, key=du.get)
    out = [(*_path_pixels(G, pu[v]), 0.0)]
    taken = set(pu[v])
    R = W.copy()
    R.remove_edges_from(zip(pu[v][:-1], pu[v][1:]))
    while R.number_of_edges():
        best = None
        for comp in nx.connected_components(R):
            if len(comp) < 2:
                continue
            starts = [n for n in comp if n in taken] or [next(iter(comp))]
            a = starts[0]
            dist, paths = nx.single_source_dijkstra(R.subgraph(comp), a, weight="length")
            b = max(dist, key=dist.get)
            reach = dist[b] - (float(radius[a]) if a in taken else 0.0)  # beyond the parent's edge
            if best is None or reach > best[0]:
                best = (reach, a, paths[b])
        if best is None or best[0] < min_extension:  # what is left lies inside the branches taken (junction knots)
            break
        _, a, path = best
        out.append((*_path_pixels(G, path), float(radius[a]) if a in taken else 0.0))
        taken.update(path)
        R.remove_edges_from(zip(path[:-1], path[1:]))
    return out
