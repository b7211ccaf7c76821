"""Tiled Priority-Flood depression filling, exactly equal to the untiled fill (Barnes 2016).

Barnes, R. (2016). Parallel priority-flood depression filling for trillion cell digital
elevation models on desktops or clusters. *Computers & Geosciences* 96, 56-68.

The DEM is cut into a deterministic grid of tiles (:func:`tile_grid`); three passes make
the result, each pass over a tile needs only that tile (plus a one-cell halo) in memory,
so every per-tile step can be its own job:

1. :func:`fill_tile` (one job per tile). The tile is filled by an ε = 0 priority flood
   whose seeds are every valid cell on the tile's perimeter (*provisional* outlets) and
   every *true* outlet: a valid cell on the DEM edge or next to nodata, which the halo
   shows even when that nodata or DEM edge lies across the tile border. Every seed on
   the tile perimeter gets its own watershed label; all true outlets share the label
   ``OCEAN``; every other cell takes the label of the cell it was flooded from. The pass
   records the *spill graph* of the tile: for each pair of adjacent labels the minimum,
   over 8-adjacent cell pairs ``(a, b)`` of those labels, of ``max(F(a), F(b))`` (``F``
   the tile-filled elevation), and the tile's perimeter ring (elevations and labels).
   (Barnes 2016 sect. 3.)
2. :func:`merge_tiles` (one job). The tiles' graphs are joined by the edges between
   facing perimeter cells of neighbouring tiles (8-adjacency, corners included; weight
   ``max(Z(a), Z(b))``, perimeter cells being seeds are unraised), and a priority flood on
   the label graph from ``OCEAN`` gives each label its spill elevation
   ``S(L) = min over graph paths L → OCEAN of the largest edge weight``.
3. :func:`finalise_tile` (one job per tile): ``W = max(F, S(label))``.

Why it is exact (ε = 0). The untiled fill is ``W(c) = min over paths c → true outlet of
max Z on the path`` (the minimal depression-free surface). ``W ≥ F``: every path from
``c`` to a true outlet reaches a seed of ``c``'s tile first. ``W ≥ S(L(c))``: walking the
optimal path, each change of label inside a tile crosses a graph edge of weight
``max(F(a), F(b)) ≤ max(W(a), W(b)) ≤ W(c)``, each tile crossing an edge of weight
``max(Z(a), Z(b)) ≤ W(c)``, and it ends at a true outlet, labelled ``OCEAN``. ``W ≤
max(F, S)``: a cell joins its label's seed by its flood path, whose cells all have
``F ≤ F(c)``; a graph path is a chain of such cell paths. All values are maxima and minima
of input elevations, no arithmetic, so the tiled result equals
:func:`kitegully.terrain.fill.priority_flood_fill` with ``epsilon=0`` bit for bit, except
for the sign of a zero: the untiled kernel writes ``zc + ε`` = ``-0.0 + 0.0`` = ``+0.0``
into cells reached at the level of a −0.0 neighbour, which depends on the order of the
flood; this module mimics it for raised cells, and −0.0 == +0.0 in any case.

The ε > 0 variant is *not* covered: an ε ramp across a flat or lake spanning tiles
depends on the D8 distance to its outlet through other tiles (and on the order of the
float additions), which the label graph does not carry. The pipeline uses ε = 0 where
flats matter (``gully.flat_routing: resolve`` and the polygon conditioning route flats
with :mod:`kitegully.terrain.flats`); only ``polygons.thalweg.mfd_catchment_area`` uses
ε = 1e-4.

As Snakemake jobs (``workflow/rules/gully.smk``, sites with a ``tiling:`` section): the
tile names come from :class:`kitegully.terrain.tiling.TilingParams` (a function of the config
alone, no checkpoint) and the windows from :func:`kitegully.terrain.tiling.split_grid`; rule
``gully_fill_tile`` (wildcard ``{tile}``) reads its window with :func:`read_tile_with_halo`
and writes ``{tile}.fill.npz`` (:meth:`TileFill.save`) and the small ``{tile}.summary.npz``;
``gully_fill_merge`` reads every summary and writes ``spill.npz``; ``gully_fill_mosaic``
finalises each tile while it writes the filled raster window by window.

Complexity: per tile O(t log t) time, O(t) memory (t cells; the float64 fill, int32
labels, a byte per cell, the queues and the label-pair list); merge O(E log V) time and
O(V + E) memory for V labels (≤ perimeter cells, ≈ 4·n/tile for tiles of side ``tile``)
and E graph edges; finalise O(t).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numba import njit

from kitegully.terrain.fill import _DC, _DR, _fifo_push, _heap_pop, _heap_push

#: Label of nodata cells.
NODATA_LABEL = 0
#: Label shared by all cells that drain to a true outlet inside their tile.
OCEAN = 1


@dataclass(frozen=True)
class Tile:
    """One tile of the deterministic grid: ``rows r0:r0+h``, ``cols c0:c0+w``.

    Attributes
    ----------
    tid : int
        Tile id, row-major over the tile grid (``ti * n_tile_cols + tj``).
    ti, tj : int
        Tile row and column in the tile grid.
    r0, c0, h, w : int
        Origin and size in cells.
    """

    tid: int
    ti: int
    tj: int
    r0: int
    c0: int
    h: int
    w: int

    @property
    def name(self) -> str:
        """Wildcard value for the tile (``r{ti}_c{tj}``)."""
        return f"r{self.ti:03d}_c{self.tj:03d}"


def tile_grid(shape: tuple[int, int], tile: int) -> list[Tile]:
    """Cut a grid of ``shape`` cells into tiles of at most ``tile`` × ``tile`` cells.

    Deterministic in ``shape`` and ``tile`` (a pure function of the site config), so a
    workflow can expand a ``{tile}`` wildcard from it without a checkpoint. The last row
    and column of tiles are smaller when ``tile`` does not divide the grid.
    """
    if tile < 1:
        raise ValueError(f"tile must be >= 1, got {tile}")
    h, w = int(shape[0]), int(shape[1])
    nr = -(-h // tile)
    nc = -(-w // tile)
    tiles = []
    for ti in range(nr):
        for tj in range(nc):
            r0, c0 = ti * tile, tj * tile
            tiles.append(Tile(ti * nc + tj, ti, tj, r0, c0, min(tile, h - r0), min(tile, w - c0)))
    return tiles


def tile_with_halo(z: np.ndarray, tile: Tile) -> np.ndarray:
    """The tile's cells with a one-cell halo (float64, NaN outside the DEM)."""
    out = np.full((tile.h + 2, tile.w + 2), np.nan)
    H, W = z.shape
    ra, rb = max(0, tile.r0 - 1), min(H, tile.r0 + tile.h + 1)
    ca, cb = max(0, tile.c0 - 1), min(W, tile.c0 + tile.w + 1)
    out[ra - tile.r0 + 1 : rb - tile.r0 + 1, ca - tile.c0 + 1 : cb - tile.c0 + 1] = z[ra:rb, ca:cb]
    return out


def read_tile_with_halo(path: str | Path, tile: Tile, halo: int = 1) -> np.ndarray:
    """Read one tile plus a halo of ``halo`` cells from a raster file (NaN outside / at nodata).

    Only the window is read, so a per-tile job never holds the whole DEM.

    Parameters
    ----------
    path : str or Path
        The raster file (band 1 is read).
    tile : Tile
        The tile's window.
    halo : int
        Width of the halo (cells).

    Returns
    -------
    ndarray (h + 2·halo, w + 2·halo) float64
        The tile with its halo; NaN outside the raster and at nodata.
    """
    import rasterio
    from rasterio.windows import Window

    with rasterio.open(path) as src:
        win = Window(tile.c0 - halo, tile.r0 - halo, tile.w + 2 * halo, tile.h + 2 * halo)
        a = src.read(1, window=win, boundless=True, masked=True)
    data = np.asarray(a.filled(np.nan) if a.dtype.kind == "f" else a.astype(np.float64).filled(np.nan), dtype=np.float64)
    return data


# --------------------------------------------------------------------------------------
# pass 1: per tile
# --------------------------------------------------------------------------------------


@njit(cache=True)
def _labelled_flood(zh, dr, dc):
    """ε = 0 priority flood of a haloed tile; returns (filled, labels, n_labels)."""
    H2, W2 = zh.shape
    h, w = H2 - 2, W2 - 2
    n = h * w
    flat = np.empty(n, dtype=np.float64)
    labels = np.zeros(n, dtype=np.int32)
    closed = np.zeros(n, dtype=np.uint8)
    hidx = np.empty(max(1024, 2 * (h + w)), dtype=np.int64)
    hkey = np.empty(hidx.size, dtype=np.float64)
    nheap = 0
    pit = np.empty(1024, dtype=np.int64)
    phead = 0
    psize = 0
    next_label = OCEAN + 1
    for r in range(h):
        for c in range(w):
            i = r * w + c
            v = zh[r + 1, c + 1]
            flat[i] = v
            if not np.isfinite(v):
                closed[i] = 1
                continue
            ocean = False
            for k in range(8):
                if not np.isfinite(zh[r + 1 + dr[k], c + 1 + dc[k]]):
                    ocean = True
                    break
            edge = r == 0 or c == 0 or r == h - 1 or c == w - 1
            if ocean or edge:
                closed[i] = 1
                if ocean:
                    labels[i] = OCEAN
                else:
                    labels[i] = next_label
                    next_label += 1
                hidx, hkey, nheap = _heap_push(hidx, hkey, nheap, i, v)
    while nheap > 0 or psize > 0:
        if psize > 0 and (nheap == 0 or flat[pit[phead]] <= hkey[0]):
            i = pit[phead]
            phead = (phead + 1) % pit.size
            psize -= 1
        else:
            i, nheap = _heap_pop(hidx, hkey, nheap)
        r = i // w
        c = i - r * w
        # ``+ 0.0`` as in the untiled kernel (zc + ε with ε = 0): turns −0.0 into +0.0
        zc = flat[i] + 0.0
        lab = labels[i]
        for k in range(8):
            rr = r + dr[k]
            cc = c + dc[k]
            if rr < 0 or cc < 0 or rr >= h or cc >= w:
                continue
            j = rr * w + cc
            if closed[j]:
                continue
            closed[j] = 1
            labels[j] = lab
            if flat[j] <= zc:
                flat[j] = zc
                pit, phead, psize = _fifo_push(pit, phead, psize, j)
            else:
                hidx, hkey, nheap = _heap_push(hidx, hkey, nheap, j, flat[j])
    return flat.reshape(h, w), labels.reshape(h, w), next_label


@njit(cache=True)
def _label_pairs(filled, labels):
    """All 8-adjacent cell pairs with different labels: (la < lb, max(F(a), F(b)))."""
    h, w = labels.shape
    cap = 1024
    la = np.empty(cap, dtype=np.int32)
    lb = np.empty(cap, dtype=np.int32)
    wt = np.empty(cap, dtype=np.float64)
    m = 0
    # forward half of the 8-neighbourhood: E, SW, S, SE
    fr = (0, 1, 1, 1)
    fc = (1, -1, 0, 1)
    for r in range(h):
        for c in range(w):
            a = labels[r, c]
            if a == 0:
                continue
            for k in range(4):
                rr = r + fr[k]
                cc = c + fc[k]
                if rr >= h or cc < 0 or cc >= w:
                    continue
                b = labels[rr, cc]
                if b == 0 or b == a:
                    continue
                if m == cap:
                    cap *= 2
                    la2 = np.empty(cap, dtype=np.int32)
                    lb2 = np.empty(cap, dtype=np.int32)
                    wt2 = np.empty(cap, dtype=np.float64)
                    la2[:m] = la[:m]
                    lb2[:m] = lb[:m]
                    wt2[:m] = wt[:m]
                    la, lb, wt = la2, lb2, wt2
                la[m] = min(a, b)
                lb[m] = max(a, b)
                wt[m] = max(filled[r, c], filled[rr, cc])
                m += 1
    return la[:m], lb[:m], wt[:m]


def _min_per_pair(la: np.ndarray, lb: np.ndarray, wt: np.ndarray, n_labels: int):
    """Reduce an edge list to one edge per label pair with its minimum weight."""
    if la.size == 0:
        return la.astype(np.int64), lb.astype(np.int64), wt
    key = la.astype(np.int64) * int(n_labels) + lb.astype(np.int64)
    order = np.lexsort((wt, key))
    key = key[order]
    first = np.ones(key.size, dtype=bool)
    first[1:] = key[1:] != key[:-1]
    k = key[first]
    return k // n_labels, k % n_labels, wt[order][first]


@dataclass
class TileFill:
    """Result of :func:`fill_tile`.

    Attributes
    ----------
    tile : Tile
    filled : ndarray (h, w) float64
        Fill with the tile edges as provisional outlets (NaN at nodata).
    labels : ndarray (h, w) int32
        Watershed label: 0 nodata, 1 (``OCEAN``) drains to a true outlet in the tile,
        ≥ 2 the perimeter seed it was flooded from.
    n_labels : int
        Labels 0..n_labels-1 are in use.
    edges : tuple of ndarray
        Spill graph inside the tile: ``(label_a, label_b, min spill elevation)``.
    """

    tile: Tile
    filled: np.ndarray
    labels: np.ndarray
    n_labels: int
    edges: tuple[np.ndarray, np.ndarray, np.ndarray]

    def perimeter(self) -> dict[str, np.ndarray]:
        """The perimeter ring (what the merge needs): elevations and labels per side."""
        f, lab = self.filled, self.labels
        return {
            "top_z": f[0].copy(), "top_l": lab[0].copy(),
            "bottom_z": f[-1].copy(), "bottom_l": lab[-1].copy(),
            "left_z": f[:, 0].copy(), "left_l": lab[:, 0].copy(),
            "right_z": f[:, -1].copy(), "right_l": lab[:, -1].copy(),
        }

    def summary(self) -> "TileSummary":
        """What the merge reads of this tile: label count, spill graph and perimeter ring."""
        return TileSummary(self.tile, self.n_labels, self.edges, self.perimeter())

    def save(self, path: str | Path) -> None:
        """Save the tile's fill, labels and summary (one ``.npz``)."""
        t = self.tile
        np.savez(
            path, tile=np.array([t.tid, t.ti, t.tj, t.r0, t.c0, t.h, t.w]), filled=self.filled,
            labels=self.labels, n_labels=self.n_labels, ea=self.edges[0], eb=self.edges[1], ew=self.edges[2],
        )

    @classmethod
    def load(cls, path: str | Path) -> "TileFill":
        """Read a tile written by :meth:`save`."""
        with np.load(path) as d:
            return cls(Tile(*(int(v) for v in d["tile"])), d["filled"], d["labels"], int(d["n_labels"]),
                       (d["ea"], d["eb"], d["ew"]))


@dataclass
class TileSummary:
    """What the merge reads of a tile: its spill graph and perimeter ring (O(perimeter))."""

    tile: Tile
    n_labels: int
    edges: tuple[np.ndarray, np.ndarray, np.ndarray]
    perimeter: dict[str, np.ndarray]

    def save(self, path: str | Path) -> None:
        """Save the tile, label count, spill graph and perimeter ring (one ``.npz``)."""
        t = self.tile
        np.savez(path, tile=np.array([t.tid, t.ti, t.tj, t.r0, t.c0, t.h, t.w]), n_labels=self.n_labels,
                 ea=self.edges[0], eb=self.edges[1], ew=self.edges[2], **self.perimeter)

    @classmethod
    def load(cls, path: str | Path) -> "TileSummary":
        """Read a summary written by :meth:`save`."""
        with np.load(path) as d:
            per = {k: d[k] for k in ("top_z", "top_l", "bottom_z", "bottom_l", "left_z", "left_l", "right_z", "right_l")}
            return cls(Tile(*(int(v) for v in d["tile"])), int(d["n_labels"]), (d["ea"], d["eb"], d["ew"]), per)


def fill_tile(z_halo: np.ndarray, tile: Tile) -> TileFill:
    """Pass 1 on one tile: provisional fill, watershed labels and the tile's spill graph.

    Parameters
    ----------
    z_halo : ndarray (h+2, w+2)
        The tile's elevations (m) with a one-cell halo (:func:`tile_with_halo` or
        :func:`read_tile_with_halo`); NaN is nodata and marks the outside of the DEM.
    tile : Tile
        The tile (its shape must match ``z_halo``).

    Returns
    -------
    TileFill

    Notes
    -----
    Complexity O(t log t) time for t cells (heap; cells inside depressions take the O(1)
    pit FIFO) and O(t) memory: the float64 fill, int32 labels, one byte per cell, the
    queues and the list of adjacent cell pairs with different labels (reduced to one
    edge per label pair by a sort).
    """
    z_halo = np.ascontiguousarray(z_halo, dtype=np.float64)
    if z_halo.shape != (tile.h + 2, tile.w + 2):
        raise ValueError(f"z_halo has shape {z_halo.shape}, tile {tile.name} needs {(tile.h + 2, tile.w + 2)}")
    filled, labels, n_labels = _labelled_flood(z_halo, _DR, _DC)
    la, lb, wt = _label_pairs(filled, labels)
    edges = _min_per_pair(la, lb, wt, int(n_labels))
    return TileFill(tile, filled, labels, int(n_labels), edges)


# --------------------------------------------------------------------------------------
# pass 2: merge
# --------------------------------------------------------------------------------------


@njit(cache=True)
def _graph_flood(n_nodes, indptr, nbr, wts):
    """Minimax priority flood on a graph from node 0 (the ocean)."""
    spill = np.full(n_nodes, np.inf)
    done = np.zeros(n_nodes, dtype=np.uint8)
    hidx = np.empty(1024, dtype=np.int64)
    hkey = np.empty(1024, dtype=np.float64)
    spill[0] = -np.inf
    hidx, hkey, nheap = _heap_push(hidx, hkey, 0, 0, -np.inf)
    while nheap > 0:
        key = hkey[0]
        u, nheap = _heap_pop(hidx, hkey, nheap)
        if done[u] or key > spill[u]:
            continue
        done[u] = 1
        for e in range(indptr[u], indptr[u + 1]):
            v = nbr[e]
            if done[v]:
                continue
            s = max(key, wts[e])
            if s < spill[v]:
                spill[v] = s
                hidx, hkey, nheap = _heap_push(hidx, hkey, nheap, v, s)
    return spill


def _cross_pairs(za, la, zb, lb, offset_a, offset_b, shifts):
    """Edges between facing perimeter strips a[i] ~ b[i + s] for s in shifts."""
    out_a, out_b, out_w = [], [], []
    n = za.size
    for s in shifts:
        ia = np.arange(max(0, -s), min(n, zb.size - s))
        ib = ia + s
        ok = (la[ia] > 0) & (lb[ib] > 0)
        ia, ib = ia[ok], ib[ok]
        out_a.append(_global(la[ia], offset_a))
        out_b.append(_global(lb[ib], offset_b))
        out_w.append(np.maximum(za[ia], zb[ib]))
    return out_a, out_b, out_w


def _global(local: np.ndarray, offset: int) -> np.ndarray:
    """Tile-local label → graph node (0 = ocean of every tile)."""
    local = np.asarray(local, dtype=np.int64)
    return np.where(local == OCEAN, 0, local - (OCEAN + 1) + offset)


@dataclass
class SpillElevations:
    """Result of :func:`merge_tiles`: the spill elevation of every label of every tile.

    ``spill[offsets[tid] + label - 2]`` is label ``label`` of tile ``tid``; node 0 is the
    ocean (−inf).
    """

    offsets: np.ndarray
    spill: np.ndarray

    def for_tile(self, tid: int, n_labels: int) -> np.ndarray:
        """Lookup array indexed by tile-local label (nodata → NaN, ocean → −inf)."""
        out = np.empty(max(n_labels, OCEAN + 1), dtype=np.float64)
        out[NODATA_LABEL] = np.nan
        out[OCEAN] = -np.inf
        o = int(self.offsets[tid])
        out[OCEAN + 1 : n_labels] = self.spill[o : o + n_labels - OCEAN - 1]
        return out

    def save(self, path: str | Path) -> None:
        """Save the offsets and spill elevations (one ``.npz``)."""
        np.savez(path, offsets=self.offsets, spill=self.spill)

    @classmethod
    def load(cls, path: str | Path) -> "SpillElevations":
        """Read spill elevations written by :meth:`save`."""
        with np.load(path) as d:
            return cls(d["offsets"], d["spill"])


def merge_tiles(summaries: list[TileSummary]) -> SpillElevations:
    """Pass 2: join the tiles' spill graphs and flood them from the true outlets.

    Parameters
    ----------
    summaries : list of TileSummary
        One per tile of one :func:`tile_grid` (any order).

    Returns
    -------
    SpillElevations

    Notes
    -----
    Complexity O(E log V) time and O(V + E) memory for V labels (at most the number of
    perimeter cells of all tiles) and E edges (label pairs inside tiles plus ≤ 3 per
    perimeter cell across tile borders); independent of the number of cells.
    """
    by_pos = {(s.tile.ti, s.tile.tj): s for s in summaries}
    if len(by_pos) != len(summaries):
        raise ValueError("two summaries for the same tile")
    nr = max(s.tile.ti for s in summaries) + 1
    nc = max(s.tile.tj for s in summaries) + 1
    if len(by_pos) != nr * nc:
        missing = sorted(Tile(0, i, j, 0, 0, 0, 0).name for i in range(nr) for j in range(nc) if (i, j) not in by_pos)
        raise ValueError(f"the merge needs every tile of the {nr} x {nc} grid; missing {', '.join(missing[:5])}")
    order = sorted(summaries, key=lambda s: s.tile.tid)
    n_tid = max(s.tile.tid for s in summaries) + 1
    offsets = np.zeros(n_tid, dtype=np.int64)
    n_nodes = 1
    for s in order:
        offsets[s.tile.tid] = n_nodes
        n_nodes += s.n_labels - (OCEAN + 1)
    ea, eb, ew = [], [], []
    for s in order:
        o = int(offsets[s.tile.tid])
        ea.append(_global(s.edges[0], o))
        eb.append(_global(s.edges[1], o))
        ew.append(np.asarray(s.edges[2], dtype=np.float64))
        p = s.perimeter
        ti, tj = s.tile.ti, s.tile.tj
        right = by_pos.get((ti, tj + 1))
        if right is not None:
            q, oq = right.perimeter, int(offsets[right.tile.tid])
            a, b, w = _cross_pairs(p["right_z"], p["right_l"], q["left_z"], q["left_l"], o, oq, (-1, 0, 1))
            ea += a; eb += b; ew += w
        down = by_pos.get((ti + 1, tj))
        if down is not None:
            q, oq = down.perimeter, int(offsets[down.tile.tid])
            a, b, w = _cross_pairs(p["bottom_z"], p["bottom_l"], q["top_z"], q["top_l"], o, oq, (-1, 0, 1))
            ea += a; eb += b; ew += w
        for dj, mine, theirs in ((1, -1, 0), (-1, 0, -1)):  # SE and SW corner neighbours
            diag = by_pos.get((ti + 1, tj + dj))
            if diag is None:
                continue
            q, oq = diag.perimeter, int(offsets[diag.tile.tid])
            if p["bottom_l"][mine] > 0 and q["top_l"][theirs] > 0:
                ea.append(_global(p["bottom_l"][mine : mine + 1 or None], o))
                eb.append(_global(q["top_l"][theirs : theirs + 1 or None], oq))
                ew.append(np.maximum(p["bottom_z"][mine : mine + 1 or None], q["top_z"][theirs : theirs + 1 or None]))
    a = np.concatenate(ea) if ea else np.zeros(0, np.int64)
    b = np.concatenate(eb) if eb else np.zeros(0, np.int64)
    w = np.concatenate(ew) if ew else np.zeros(0)
    keep = a != b
    a, b, w = a[keep], b[keep], w[keep]
    # undirected CSR
    src = np.concatenate([a, b])
    dst = np.concatenate([b, a])
    ww = np.concatenate([w, w])
    o = np.argsort(src, kind="stable")
    indptr = np.zeros(n_nodes + 1, dtype=np.int64)
    np.cumsum(np.bincount(src, minlength=n_nodes), out=indptr[1:])
    spill = _graph_flood(n_nodes, indptr, dst[o], ww[o])
    if n_nodes > 1 and not np.all(np.isfinite(spill[1:])):
        raise RuntimeError(f"{int(np.sum(~np.isfinite(spill[1:])))} watershed labels reach no outlet (tiles missing?)")
    return SpillElevations(offsets, spill)


# --------------------------------------------------------------------------------------
# pass 3: finalise
# --------------------------------------------------------------------------------------


def finalise_tile(tf: TileFill, spill: SpillElevations) -> np.ndarray:
    """Pass 3 on one tile: ``max(provisional fill, spill elevation of the cell's label)``.

    Returns the tile's part of the filled DEM (float64, NaN at nodata). O(t).
    """
    lut = spill.for_tile(tf.tile.tid, tf.n_labels)
    s = lut[tf.labels]
    # raised cells get ``S + 0.0`` like the untiled kernel's ``zc + ε`` (sign of zero)
    return np.where(s > tf.filled, s + 0.0, tf.filled)


def tiled_priority_flood_fill(z: np.ndarray, tile: int) -> np.ndarray:
    """All three passes in one process (for tests and benchmarks; a workflow runs them as jobs).

    Parameters
    ----------
    z : ndarray (H, W)
        Elevations (m), NaN nodata.
    tile : int
        Tile side (cells).

    Returns
    -------
    ndarray (H, W) float64
        Equal, bit for bit, to ``priority_flood_fill(z, epsilon=0)[0]``.

    Notes
    -----
    O(n log t) time; this driver keeps all tiles' fills in memory (O(n)) — the per-job
    passes need O(t) each plus O(V + E) for the merge.
    """
    z = np.asarray(z, dtype=np.float64)
    if z.ndim != 2:
        raise ValueError("z must be a 2-D array")
    tiles = tile_grid(z.shape, tile)
    fills = [fill_tile(tile_with_halo(z, t), t) for t in tiles]
    spill = merge_tiles([f.summary() for f in fills])
    out = np.empty(z.shape, dtype=np.float64)
    for f in fills:
        t = f.tile
        out[t.r0 : t.r0 + t.h, t.c0 : t.c0 + t.w] = finalise_tile(f, spill)
    return out
