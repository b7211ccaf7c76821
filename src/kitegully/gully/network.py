"""Gully network (Fig. 3 g-j): snap heads, trace steepest descent, stream order, lines.

Heads are snapped onto the gully within a radius set from their digitising error ([I]
lowest cell within 3σ = 6 m) and traced on the depression-free DEM (optionally lightly
smoothed first; flats resolved or ε gradient), head after head; a path stops at the DEM edge or nodata (outlet) or
merges into a path traced before. The traced cells form a forest of trees that drain
to outlets; stream order is Strahler's, and the lines are split at heads and
confluences into segments that carry their order and length.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import geopandas as gpd
import numpy as np
from numba import njit
from shapely import linestrings

from kitegully.io.raster import GridSpec
from kitegully.terrain.flow import END_OUTLET, END_PIT, trace_paths

if TYPE_CHECKING:
    from pathlib import Path


#: How a digitised head is moved onto the gully (``gully.head_snap``).
HEAD_SNAPS = ("lowest", "deepest", "patch", "plane", "incision", "relief", "posterior")


def snap_heads(
    z: np.ndarray,
    grid: GridSpec,
    x: np.ndarray,
    y: np.ndarray,
    radius_m: float,
    method: str = "lowest",
    depth: np.ndarray | None = None,
    patches: np.ndarray | None = None,
    smoothed: np.ndarray | None = None,
    incised: np.ndarray | None = None,
    relief: np.ndarray | None = None,
    relief_noise_m: float | None = None,
    relief_k: float = 3.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Snap digitised heads onto a valid cell whose centre lies within ``radius_m``.

    Parameters
    ----------
    z : ndarray (H, W)
        DEM (m), NaN nodata; candidates must be valid on it.
    grid : GridSpec
        Its grid.
    x, y : ndarray
        Head coordinates (m).
    radius_m : float
        Search radius (m), e.g. three times the digitising SD of the heads.
    method : str
        ``lowest``: the lowest cell of ``z``; ``deepest``: the cell of greatest ``depth``
        (the incision below the smoothed surface, Fig. 3 a-d); ``patch``: the nearest cell
        of a kept depth patch (``patches`` > 0, Fig. 3 e-f), or the lowest cell when no
        patch is within reach; ``plane``: the lowest cell below the local slope plane,
        i.e. the lowest of ``z − g·(p − p_head)`` with ``g`` the gradient of ``smoothed`` at
        the head. [I] ``plane`` is ``lowest`` without its downslope bias: on a field of slope
        S the plain lowest cell within r lies up to r·S below the head (0.6 m at r 6 m and
        S 10 %), more than the relief of a shallow head (0.15–0.5 m), so a head digitised a
        few metres beside its incision lands downslope beside it; below the local plane only
        an incision is low, and vegetation (above the plane) never is, unlike ``deepest``;
        but in a concave hollow every cell at the radius lies about κr²/2 below the tangent
        plane, so ``plane`` is pulled to the radius there. ``incision``: the *nearest* cell
        of a visible incision (``incised``, :func:`kitegully.gully.relief.incision_map` and
        :func:`~kitegully.gully.relief.visible_incisions`), or the digitised cell itself when
        no incision lies within reach. [I] The operator digitised a head on an incision seen
        on the hillshade, with an isotropic Gaussian error of SD radius/3; of the cells where
        the DSM shows an incision, the nearest one is the most likely true position (the
        Gaussian likelihood falls with distance alone). Elevation does not enter, so neither
        the slope (r·S of ``lowest``) nor the curvature (κr²/2 of ``plane``) biases it; the
        incision map is made against the ground surface at head scale (σ 2 m), where a
        field's curvature adds only κσ² ≈ 0.04 m at κ 0.01 m⁻¹. Without an incision in
        reach nothing in the data says where to move the head, and its error is
        zero-mean: it stays where it was digitised.
        ``relief``: the cell of greatest head-scale depth below the ground surface
        (``relief``, :func:`kitegully.gully.relief.head_scale_relief`, σ 2 m). [I] Within the
        99 % error circle of a digitised head, the cell where the DSM is most incised at the
        scale of a head is in the channel: the Gaussian keeps a plane exactly (no r·S slope
        bias), a field's curvature adds only κσh² ≈ 0.04 m (not κr²/2 ≈ 0.2 m at r 6 m), and
        vegetation stands above the ground surface (never deep, unlike ``deepest`` on the
        σ 6 m depth map of the DSM). Like ``lowest`` it may move the head down its own
        channel (by less than r).
        ``posterior``: the cell of greatest posterior probability of being the head, from
        the digitising error and the head-scale relief together (``relief``,
        ``relief_noise_m`` = ρ, ``relief_k`` = k). [I] The operator's error is an isotropic
        Gaussian of SD σ = radius/3 (the radius is 3 σ), so the prior of a cell at distance
        d is ∝ exp(−d²/2σ²). Away from a head the relief map scatters about 0 with the
        surface's own spread ρ = max(DSM noise, micro-relief: furrows, plant gaps), which is
        what puts maxima off the gully; at a visible head it is about its depth D ≥ kρ (the
        visibility rule). The log-likelihood ratio of relief r for a head of depth D against
        that background is (rD − D²/2)/ρ², i.e. kr/ρ + const for the shallowest visible
        head D = kρ, the conservative choice when D is unknown. So the head goes to the
        minimum of d²/2σ² − k r/ρ: a cell 1.2ρ deeper is worth moving 4 m away from a head
        digitised 1.5 m beside its channel at σ 2 m, and ``relief`` is the limit ρ → 0
        (any deeper cell wins, wherever it lies within the radius).
    depth, patches : ndarray (H, W), optional
        Depth map (m) for ``deepest``, patch labels for ``patch``.
    smoothed : ndarray (H, W), optional
        The Gaussian-smoothed DEM of the depth map (Fig. 3 a-b), for ``plane``: its
        gradient at the head is the local slope plane (field-scale, without the incision).
    incised : ndarray bool (H, W), optional
        Visible incision cells leading into a channel, for ``incision``.
    relief : ndarray (H, W), optional
        Head-scale depth below the ground surface (m), for ``relief`` and ``posterior``.
    relief_noise_m : float, optional
        ρ of ``posterior`` (m): the spread of ``relief`` away from heads.
    relief_k : float
        k of ``posterior``: the visibility threshold in units of ρ.

    Returns
    -------
    index : ndarray int64
        Flat cell index of each head (-1 when no valid cell is within reach).
    inside : ndarray bool
        Heads that could be snapped (inside the DEM, on valid data).

    Notes
    -----
    Complexity O(k r²) for k heads and a radius of r cells.
    """
    if method not in HEAD_SNAPS:
        raise ValueError(f"head snapping must be one of {HEAD_SNAPS}, got {method!r}")
    needs = {"deepest": ("depth map", depth), "patch": ("patch labels", patches), "plane": ("smoothed DEM", smoothed),
             "incision": ("incision map", incised), "relief": ("head-scale relief map", relief),
             "posterior": ("head-scale relief map", relief)}
    if np.size(x) == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=bool)
    if method in needs and needs[method][1] is None:
        raise ValueError(f"head snapping {method!r} needs the {needs[method][0]}")
    if method == "posterior" and not (relief_noise_m is not None and relief_noise_m > 0 and radius_m > 0):
        raise ValueError("head snapping 'posterior' needs a positive relief noise and search radius")
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    row, col = grid.rowcol(x, y)
    rad = max(0, int(np.ceil(radius_m / grid.cell)))
    off = np.arange(-rad, rad + 1)
    dr, dc = np.meshgrid(off, off, indexing="ij")
    dr, dc = dr.ravel(), dc.ravel()
    r0 = np.rint(row).astype(np.int64)
    c0 = np.rint(col).astype(np.int64)
    rr = r0[:, None] + dr[None, :]
    cc = c0[:, None] + dc[None, :]
    # distance from the point to the candidate cell centres
    dist = np.hypot((rr - row[:, None]) * grid.cell, (cc - col[:, None]) * grid.cell)
    ok = (rr >= 0) & (cc >= 0) & (rr < grid.height) & (cc < grid.width) & (dist <= max(radius_m, 0.5 * grid.cell * np.sqrt(2)))
    zz = np.full(rr.shape, np.inf)
    zz[ok] = z[rr[ok], cc[ok]]
    zz[~np.isfinite(zz)] = np.inf
    valid = np.isfinite(zz)
    if method == "deepest":
        cost = np.full(rr.shape, np.inf)
        cost[ok] = -np.asarray(depth)[rr[ok], cc[ok]]
        cost[~valid | ~np.isfinite(cost)] = np.inf
        # a candidate without a finite depth keeps the head on the lowest cell
        cost = np.where(np.isfinite(cost).any(axis=1)[:, None], cost, zz)
    elif method == "patch":
        on = np.zeros(rr.shape, dtype=bool)
        on[ok] = np.asarray(patches)[rr[ok], cc[ok]] > 0
        on &= valid
        cost = np.where(on.any(axis=1)[:, None], np.where(on, dist, np.inf), zz)
    elif method == "plane":
        gr, gc = _plane_gradient(np.asarray(smoothed), r0, c0)
        cost = zz - gr[:, None] * dr[None, :] - gc[:, None] * dc[None, :]
    elif method == "incision":
        on = np.zeros(rr.shape, dtype=bool)
        on[ok] = np.asarray(incised)[rr[ok], cc[ok]]
        on &= valid
        # nearest incised cell; none in reach: the valid cell nearest the digitised point (the point itself)
        cost = np.where(on.any(axis=1)[:, None], np.where(on, dist, np.inf), np.where(valid, dist, np.inf))
    elif method == "relief":
        cost = np.full(rr.shape, np.inf)
        cost[ok] = -np.asarray(relief)[rr[ok], cc[ok]]
        cost[~valid | ~np.isfinite(cost)] = np.inf
        cost = np.where(np.isfinite(cost).any(axis=1)[:, None], cost, np.where(valid, dist, np.inf))
    elif method == "posterior":
        sigma = radius_m / 3.0
        cost = np.full(rr.shape, np.inf)
        cost[ok] = (dist[ok] ** 2 / (2.0 * sigma**2)
                    - relief_k * np.asarray(relief, dtype=np.float64)[rr[ok], cc[ok]] / relief_noise_m)
        cost[~valid | ~np.isfinite(cost)] = np.inf
        cost = np.where(np.isfinite(cost).any(axis=1)[:, None], cost, np.where(valid, dist, np.inf))
    else:
        cost = zz
    best = np.argmin(cost, axis=1)
    k = np.arange(x.size)
    inside = valid[k, best]
    index = np.where(inside, rr[k, best] * grid.width + cc[k, best], -1)
    return index.astype(np.int64), inside


def _plane_gradient(smoothed: np.ndarray, r0: np.ndarray, c0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Gradient (m per cell along rows and columns) of ``smoothed`` at cells (r0, c0).

    Central differences, one-sided at the edge; 0 where a neighbour is off the grid or NaN
    (the plain lowest cell then decides). O(k) for k heads.
    """
    h, w = smoothed.shape
    out = []
    for axis, n in ((0, h), (1, w)):
        lo = np.clip(np.where(axis == 0, r0, c0) - 1, 0, n - 1)
        hi = np.clip(np.where(axis == 0, r0, c0) + 1, 0, n - 1)
        ri = np.clip(r0, 0, h - 1)
        ci = np.clip(c0, 0, w - 1)
        a = smoothed[lo, ci] if axis == 0 else smoothed[ri, lo]
        b = smoothed[hi, ci] if axis == 0 else smoothed[ri, hi]
        g = (b - a) / np.maximum(hi - lo, 1)
        out.append(np.where(np.isfinite(g), g, 0.0))
    return out[0], out[1]


@njit(cache=True)
def topological_order(pos_down: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cells of a downstream forest in topological order, heads first (Kahn's algorithm).

    Parameters
    ----------
    pos_down : ndarray int64 (n,)
        Index of each cell's downstream neighbour, -1 at an outlet.

    Returns
    -------
    order : ndarray int64 (n,)
        Cell indices, every cell after all cells that drain into it.
    indeg : ndarray int64 (n,)
        Number of cells draining into each cell (0 at a head).

    Notes
    -----
    O(n).
    """
    n = pos_down.size
    indeg = np.zeros(n, dtype=np.int64)
    for i in range(n):
        if pos_down[i] >= 0:
            indeg[pos_down[i]] += 1
    order = np.empty(n, dtype=np.int64)
    left = indeg.copy()
    qh = 0
    qt = 0
    for i in range(n):
        if indeg[i] == 0:
            order[qt] = i
            qt += 1
    while qh < qt:
        i = order[qh]
        qh += 1
        j = pos_down[i]
        if j >= 0:
            left[j] -= 1
            if left[j] == 0:
                order[qt] = j
                qt += 1
    return order[:qt], indeg


@njit(cache=True)
def _strahler_and_segments(pos_down):
    n = pos_down.size
    queue, indeg = topological_order(pos_down)
    # Strahler, heads first: max of inflows, +1 if the max is shared.
    order = np.zeros(n, dtype=np.int64)
    best = np.zeros(n, dtype=np.int64)
    nbest = np.zeros(n, dtype=np.int64)
    for q in range(queue.size):
        i = queue[q]
        if indeg[i] == 0:
            order[i] = 1
        elif nbest[i] >= 2:
            order[i] = best[i] + 1
        else:
            order[i] = best[i]
        j = pos_down[i]
        if j >= 0:
            if order[i] > best[j]:
                best[j] = order[i]
                nbest[j] = 1
            elif order[i] == best[j]:
                nbest[j] += 1
    # Segments start at heads and confluences and run down to the next confluence
    # (included as last vertex) or an outlet.
    verts = np.empty(2 * n, dtype=np.int64)
    seg_start = np.empty(n + 1, dtype=np.int64)
    seg_order = np.empty(n, dtype=np.int64)
    nv = 0
    ns = 0
    for s in range(n):
        if indeg[s] == 1:
            continue
        seg_start[ns] = nv
        seg_order[ns] = order[s]
        ns += 1
        i = s
        while True:
            verts[nv] = i
            nv += 1
            j = pos_down[i]
            if j < 0:
                break
            if indeg[j] != 1:
                verts[nv] = j
                nv += 1
                break
            i = j
    seg_start[ns] = nv
    return order, indeg, verts[:nv], seg_start[: ns + 1], seg_order[:ns]


@dataclass
class GullyNetwork:
    """A traced network on a grid.

    Attributes
    ----------
    cells : ndarray int64
        Flat indices of the traced cells (unique).
    pos_down : ndarray int64
        Position (in ``cells``) of the next cell downstream, -1 at outlets and pits.
    order : ndarray int64
        Strahler order of every traced cell.
    seg_vertices, seg_start, seg_order : ndarray int64
        Segment ``s`` is ``cells[seg_vertices[seg_start[s]:seg_start[s + 1]]]``.
    head_cells : ndarray int64
        Snapped head cells (flat indices), -1 for heads outside the DEM.
    ends : ndarray int64
        How each head's path ended (see :mod:`kitegully.terrain.flow`).
    shape : tuple
        Grid shape (H, W).
    """

    cells: np.ndarray
    pos_down: np.ndarray
    order: np.ndarray
    seg_vertices: np.ndarray
    seg_start: np.ndarray
    seg_order: np.ndarray
    head_cells: np.ndarray
    ends: np.ndarray
    shape: tuple[int, int]

    @property
    def n_segments(self) -> int:
        """Number of traced segments."""
        return int(self.seg_order.size)

    def mask(self) -> np.ndarray:
        """Boolean raster of the traced cells."""
        m = np.zeros(self.shape[0] * self.shape[1], dtype=bool)
        m[self.cells] = True
        return m.reshape(self.shape)

    def n_paths_not_at_outlet(self) -> int:
        """Paths that ended in a pit (never happens on a filled DEM with ε > 0 or flats resolved)."""
        return int(np.sum(self.ends == END_PIT))

    def n_paths_to_outlet(self) -> int:
        """Paths that reached an outlet (``ends == END_OUTLET``)."""
        return int(np.sum(self.ends == END_OUTLET))

    def save(self, path: str | Path) -> None:
        """Write the network to a ``.npz`` file (arrays only, no pickle)."""
        np.savez_compressed(
            path, cells=self.cells, pos_down=self.pos_down, order=self.order, seg_vertices=self.seg_vertices,
            seg_start=self.seg_start, seg_order=self.seg_order, head_cells=self.head_cells, ends=self.ends,
            shape=np.asarray(self.shape, dtype=np.int64),
        )

    @classmethod
    def load(cls, path: str | Path) -> "GullyNetwork":
        """Read a network written by :meth:`save`."""
        with np.load(path, allow_pickle=False) as f:
            return cls(
                f["cells"], f["pos_down"], f["order"], f["seg_vertices"], f["seg_start"], f["seg_order"],
                f["head_cells"], f["ends"], tuple(int(v) for v in f["shape"]),
            )


def trace_network(filled: np.ndarray, head_cells: np.ndarray, directions: np.ndarray | None = None) -> GullyNetwork:
    """Trace the network from the (snapped) heads on a depression-free DEM.

    Heads with index -1 are skipped. With ``directions`` (D8 codes, e.g. flats resolved by
    :func:`kitegully.terrain.flats.flow_directions`) the paths follow them instead of the
    steepest descent on ``filled``. Complexity O(L log L) in the number of traced cells.

    Parameters
    ----------
    filled : ndarray (H, W)
        Depression-free DEM (m).
    head_cells : ndarray int64
        Flat cell indices of the heads, -1 for heads to skip.
    directions : ndarray (H, W) uint8 or None
        D8 codes to follow; None: steepest descent on ``filled``.

    Returns
    -------
    GullyNetwork
        The traced network; ``ends`` is -1 for skipped heads.
    """
    head_cells = np.asarray(head_cells, dtype=np.int64)
    use = head_cells[head_cells >= 0]
    cells, down, _starts, ends = trace_paths(filled, use, directions)
    all_ends = np.full(head_cells.size, -1, dtype=np.int64)
    all_ends[head_cells >= 0] = ends
    srt = np.argsort(cells, kind="stable")
    pos_down = np.full(cells.size, -1, dtype=np.int64)
    has = down >= 0
    if cells.size:
        pos_down[has] = srt[np.searchsorted(cells[srt], down[has])]
    order, _indeg, verts, seg_start, seg_order = _strahler_and_segments(pos_down)
    return GullyNetwork(cells, pos_down, order, verts, seg_start, seg_order, head_cells, all_ends, tuple(filled.shape))


def network_lines(net: GullyNetwork, grid: GridSpec, keep: np.ndarray | None = None) -> gpd.GeoDataFrame:
    """Network segments as lines through cell centres, with ``stream_order`` and ``length_m``.

    Parameters
    ----------
    keep : ndarray bool (H, W), optional
        If given, only runs of consecutive segment vertices on ``keep`` cells are kept
        (the network clipped to a map); a run needs at least two vertices.
    """
    geoms, orders, seg_ids = [], [], []
    for s in range(net.n_segments):
        v = net.cells[net.seg_vertices[net.seg_start[s] : net.seg_start[s + 1]]]
        if keep is None:
            runs = [v] if v.size >= 2 else []
        else:
            ok = keep.ravel()[v]
            edges = np.flatnonzero(np.diff(np.concatenate([[0], ok.astype(np.int8), [0]])))
            runs = [v[a:b] for a, b in zip(edges[::2], edges[1::2]) if b - a >= 2]
        for run in runs:
            geoms.append(grid.flat_xy(run))
            orders.append(int(net.seg_order[s]))
            seg_ids.append(s + 1)
    if geoms:
        ind = np.repeat(np.arange(len(geoms)), [g.shape[0] for g in geoms])
        lines = linestrings(np.concatenate(geoms), indices=ind)
    else:
        lines = []
    gdf = gpd.GeoDataFrame(
        {"segment_id": np.array(seg_ids, dtype=np.int64), "stream_order": np.array(orders, dtype=np.int64)},
        geometry=gpd.GeoSeries(lines, crs=grid.crs),
        crs=grid.crs,
    )
    gdf["length_m"] = gdf.geometry.length
    return gdf
