"""Channels that enter the DEM across its edge (``gully.edge_inlets``).

The paper traces the network from gully heads digitised on the DEM (Feurer et al. 2018,
Fig. 3 g-j). A channel whose head lies upstream of the surveyed area, such as a wadi that
enters the kite survey from the catchment above it, has no head on the DEM, so no path
runs down its reach above the first tributary that joins it, although the DEM shows it and
the field network maps it. A person digitising heads on the hillshade would mark where such
a channel enters; this module finds those points from the data:

* the *outer edge* is the DEM's nodata connected to the grid's border (the survey's outline),
  not interior holes such as open water;
* the *edge band* is the strip within ``reach_m`` of that edge (the stage passes 2σ of the
  depth map: within it the Gaussian window is cut by the edge, and the DSM's outermost
  columns are the block's weakest); a depth patch that has cells two cells inside the edge
  (a cell next to nodata is an outlet, where every traced path ends) *crosses* the band;
* a *candidate* is a cell of such a patch where the band ends (``reach_m`` from the edge);
  it is an *inlet* when its D8 path runs inside the depth patches for another ``reach_m``
  inward (the channel carries water into the DEM: a channel leaving it drains back to the
  edge, a pit or a short scour at the edge does not reach the band's end), and at least half
  of that stretch is *incised* at the head scale (the operator's visibility rule,
  :func:`kitegully.gully.relief.head_scale_relief` >= k·max(σ_z, ρ)), as the automatic head
  detector asks of a channel. The σ-scale depth map alone also marks the concave foot of a
  steep slope (1-1.7 m deep on a valley side of ensemble twin ens1, where the DSM equals the
  true DTM); only 0-32 % of such stretches are incised, 100 % of the wadi's;
* the inlet's *course* across the band is the shortest 8-connected way through its patch
  from the candidate to the patch's cells two cells inside the edge, and half of it must be
  incised too (the channel crosses the edge, not a slope foot beside it). Flow is read
  where the band ends and not at the edge itself because the floor of an entering channel
  need not fall inward there: on ensemble twin ens3 the wadi's floor rises 0.35 m over its
  first 10 m on the true DTM (0.8 m on the DSM), so from the edge every cell of it drains out;
* each run of candidates gives at most one inlet, its deepest that qualifies.
"""

from __future__ import annotations

import cv2
import numpy as np
from scipy import ndimage
from skimage.graph import MCP_Geometric

from kitegully.terrain.flow import D8_OFFSETS, trace_paths


def outer_edge_distance(valid: np.ndarray) -> np.ndarray:
    """Distance (cells) of every cell from the DEM's outer edge: nodata connected to the grid border.

    Parameters
    ----------
    valid : ndarray bool (H, W)
        Cells with an elevation.

    Returns
    -------
    ndarray float32 (H, W)
        Euclidean distance (cells) to the nearest outer-nodata cell or to the border frame
        (one cell beyond the grid); 0 on outer nodata. Interior holes do not count as edge.
        O(n) (labelling and OpenCV's exact distance transform).
    """
    nodata = np.pad(~np.asarray(valid, dtype=bool), 1, constant_values=True)
    labels, _n = ndimage.label(nodata, structure=np.ones((3, 3), dtype=bool))
    outside = labels == labels[0, 0]
    del labels
    dist = cv2.distanceTransform(np.logical_not(outside).view(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    return dist[1:-1, 1:-1]


def edge_inlets(
    patches: np.ndarray,
    depth: np.ndarray,
    valid: np.ndarray,
    filled: np.ndarray,
    directions: np.ndarray | None,
    cell_m: float,
    reach_m: float,
    incised: np.ndarray | None = None,
) -> tuple[np.ndarray, list[np.ndarray]]:
    """Channels that enter the DEM across its outer edge, and their courses across the edge band.

    Parameters
    ----------
    patches : ndarray int (H, W)
        Kept depth patches (> 0), :func:`kitegully.gully.patches.depth_patches`.
    depth : ndarray (H, W)
        The depth map the patches come from (m).
    valid : ndarray bool (H, W)
        Cells of the DEM the paths are traced on (open water and the survey's outside False).
    filled, directions
        The depression-free DEM and its D8 directions (or None for steepest descent), as
        :func:`kitegully.terrain.flow.trace_paths` takes them.
    cell_m : float
        Cell size (m).
    reach_m : float
        Width of the edge band (m) and the length of the inward path a candidate must follow
        in the depth patches ([I] the stage uses 2σ of the depth map: within it the smoothing's
        window is cut by the edge, so a patch there may be an edge effect rather than a channel).
    incised : ndarray bool (H, W), optional
        Cells incised at the head scale; when given, at least half of a candidate's inward path
        and half of its course across the band must be incised (a channel, not a slope foot).

    Returns
    -------
    starts : ndarray int64
        Flat index of each inlet's first cell, two cells inside the edge, deepest inlet first.
    courses : list of ndarray int64
        Per inlet, the cells of its course from ``starts`` across the band to the candidate
        where the band ends (8-connected, in downstream order); :func:`route_courses` makes a
        D8 direction raster follow them.

    Notes
    -----
    O(n) for the edge distance and the patch labels, O(L) for the candidates' paths (traced
    together, merging where they meet), O(k·r), vectorised, to follow the k candidates while
    they stay in the patches (r ≈ 4·``reach_m``/``cell_m`` steps at most), and one minimum-cost
    search per inlet in a window of its patch.
    """
    if patches.shape != valid.shape or depth.shape != valid.shape or (incised is not None and incised.shape != valid.shape):
        raise ValueError("patches, depth, valid and incised must have the same shape")
    if not reach_m > 0:
        raise ValueError(f"reach_m must be > 0, got {reach_m!r}")
    none = (np.zeros(0, dtype=np.int64), [])
    dist2d = outer_edge_distance(valid)
    dist = dist2d.ravel()
    in_patch2d = (patches > 0) & valid
    in_patch = in_patch2d.ravel()
    reach_cells = reach_m / cell_m
    edge_ring = in_patch2d & (dist2d > 1.5) & (dist2d <= 2.5)  # not next to nodata: an outlet there ends every path
    if not edge_ring.any():
        return none
    plab, _np = ndimage.label(in_patch2d, structure=np.ones((3, 3), dtype=bool))
    crossing = np.unique(plab[edge_ring])
    band_end = in_patch2d & (dist2d > reach_cells - 0.5) & (dist2d <= reach_cells + 0.5) & np.isin(plab, crossing[crossing > 0])
    if not band_end.any():
        return none
    runs, _n = ndimage.label(band_end, structure=np.ones((3, 3), dtype=bool))
    cand = np.flatnonzero(runs.ravel())
    cells, down, _starts, _ends = trace_paths(filled, cand, directions)  # paths merge where they meet
    order = np.argsort(cells, kind="stable")
    sorted_cells, next_of = cells[order], down[order]
    flat_incised = np.ones_like(in_patch) if incised is None else np.asarray(incised, dtype=bool).ravel()
    pos = cand.copy()
    alive = np.ones(cand.size, dtype=bool)
    ok = np.zeros(cand.size, dtype=bool)
    walked = np.zeros(cand.size, dtype=np.int64)
    n_incised = np.zeros(cand.size, dtype=np.int64)
    goal = 2.0 * reach_cells  # another band's width inward
    for _step in range(int(np.ceil(4 * reach_cells)) + 8):  # a path wanders at most ~4x the straight distance
        alive &= in_patch[pos]
        walked += alive
        n_incised += alive & flat_incised[pos]
        reached = alive & (dist[pos] >= goal)
        ok |= reached & (2 * n_incised >= walked)
        alive &= ~reached
        if not alive.any():
            break
        nxt = next_of[np.searchsorted(sorted_cells, pos[alive])]
        idx = np.flatnonzero(alive)
        alive[idx[nxt < 0]] = False
        pos[idx[nxt >= 0]] = nxt[nxt >= 0]
    acc = cand[ok]
    if not acc.size:
        return none
    # per run of candidates, its deepest accepted cell whose course crosses the band as a channel
    lab = runs.ravel()[acc]
    key = np.lexsort((-np.nan_to_num(depth.ravel()[acc], nan=-np.inf), lab))
    starts, courses, depths, done = [], [], [], set()
    for i, run in zip(acc[key], lab[key]):
        if run in done:
            continue
        course = band_course(int(i), plab, dist2d, edge_ring, reach_cells)
        if course is None or (incised is not None and 2 * int(flat_incised[course].sum()) < course.size):
            continue
        done.add(run)
        starts.append(int(course[0]))
        courses.append(course)
        depths.append(float(np.nan_to_num(depth.ravel()[i], nan=-np.inf)))
    if not starts:
        return none
    srt = np.argsort(-np.asarray(depths), kind="stable")
    return np.asarray(starts, dtype=np.int64)[srt], [courses[k] for k in srt]


def band_course(cell: int, plab: np.ndarray, dist: np.ndarray, edge_ring: np.ndarray, reach_cells: float) -> np.ndarray | None:
    """The shortest 8-connected way from ``cell`` through its depth patch to the patch's edge-ring cells.

    Parameters
    ----------
    cell : int
        Flat index of the candidate where the band ends.
    plab : ndarray int (H, W)
        Labelled depth patches (0 outside).
    dist : ndarray (H, W)
        :func:`outer_edge_distance` (cells).
    edge_ring : ndarray bool (H, W)
        Patch cells two cells inside the edge.
    reach_cells : float
        Band width (cells): the way stays within it (and half a cell beyond).

    Returns
    -------
    ndarray int64 or None
        Flat indices from the edge-ring cell to ``cell``; None when the patch gives no way
        inside the band (it reaches the edge only beyond it).

    Notes
    -----
    O(m log m) in the m cells of a window of ±2·``reach_cells`` around ``cell``
    (:class:`skimage.graph.MCP_Geometric`).
    """
    h, w = plab.shape
    r0, c0 = divmod(cell, w)
    k = int(np.ceil(2 * reach_cells)) + 2
    ra, rb, ca, cb = max(r0 - k, 0), min(r0 + k + 1, h), max(c0 - k, 0), min(c0 + k + 1, w)
    lab = plab[ra:rb, ca:cb]
    inside = (lab == plab[r0, c0]) & (dist[ra:rb, ca:cb] > 1.5) & (dist[ra:rb, ca:cb] <= reach_cells + 0.5)
    ends = inside & edge_ring[ra:rb, ca:cb]
    if not ends.any():
        return None
    mcp = MCP_Geometric(np.where(inside, 1.0, np.inf), fully_connected=True)
    cost, _tb = mcp.find_costs([(r0 - ra, c0 - ca)])
    er, ec = np.nonzero(ends)
    best = int(np.argmin(cost[er, ec]))
    if not np.isfinite(cost[er[best], ec[best]]):
        return None
    path = np.asarray(mcp.traceback((int(er[best]), int(ec[best]))))[::-1]  # edge ring first
    return ((path[:, 0] + ra) * w + path[:, 1] + ca).astype(np.int64)


def route_courses(directions: np.ndarray, courses: list[np.ndarray]) -> np.ndarray:
    """A copy of a D8 direction raster that follows each course cell to cell (its last cell keeps its own code).

    Parameters
    ----------
    directions : ndarray uint8 (H, W)
        D8 codes (:data:`kitegully.terrain.flow.D8_OFFSETS` order, 255 none).
    courses : list of ndarray int64
        Flat indices of 8-connected cell sequences, downstream order (:func:`edge_inlets`).

    Returns
    -------
    ndarray uint8 (H, W)
    """
    out = np.array(directions, dtype=np.uint8, copy=True)
    flat = out.ravel()
    w = out.shape[1]
    code = {(int(dr), int(dc)): k for k, (dr, dc) in enumerate(D8_OFFSETS)}
    for course in courses:
        r, c = np.divmod(np.asarray(course, dtype=np.int64), w)
        for i in range(course.size - 1):
            flat[course[i]] = code[(int(r[i + 1] - r[i]), int(c[i + 1] - c[i]))]
    return out
