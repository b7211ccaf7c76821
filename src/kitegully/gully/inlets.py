"""Channels that enter the DEM across its edge (``gully.edge_inlets``).

The paper traces the network from gully heads digitised on the DEM (Feurer et al. 2018,
Fig. 3 g-j). A channel whose head lies upstream of the surveyed area, such as a wadi that
enters the kite survey from the catchment above it, has no head on the DEM, so no path
runs down its reach above the first tributary that joins it, although the DEM shows it and
the field network maps it. A person digitising heads on the hillshade would mark where such
a channel enters; this module finds those points from the data:

* the *outer edge* is the DEM's nodata connected to the grid's border (the survey's outline),
  not interior holes such as open water;
* a *candidate* is a depth-patch cell (steps e-f: depth > threshold, patch volume >= the
  minimum) two cells inside that edge (a cell next to nodata is an outlet, where every
  traced path ends); every candidate is tried, and each run of them along the edge gives at
  most one inlet, its deepest that qualifies (on a ragged photogrammetric edge the deepest
  may lie beside a nodata notch in the channel's floor and drain out into it);
* it is an *inlet* when its D8 path runs inside the depth patches until it is at least
  ``reach_m`` from the edge (the channel carries water into the DEM: a channel leaving the
  DEM drains straight to the edge, a pit or a short scour at the edge stays near it), and
  at least half of that stretch is *incised* at the head scale (the operator's visibility
  rule, :func:`kitegully.gully.heads.head_scale_relief` >= k·max(σ_z, ρ)), as the automatic
  head detector asks of a channel. The σ-scale depth map alone also marks the concave foot
  of a steep slope (1-1.7 m deep on a valley side of ensemble twin ens1, where the DSM equals
  the true DTM); only 0-32 % of such stretches are incised, 100 % of the wadi's.
"""

from __future__ import annotations

import cv2
import numpy as np
from scipy import ndimage

from kitegully.terrain.flow import trace_paths


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
) -> np.ndarray:
    """Start cells of channels that enter the DEM across its outer edge.

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
        How far from the edge (m) a candidate's path must get while it stays in the depth
        patches ([I] the stage uses 2σ of the depth map: within it the smoothing's window is
        cut by the edge, so a patch there may be an edge effect rather than a channel).
    incised : ndarray bool (H, W), optional
        Cells incised at the head scale; when given, at least half of a candidate's path up to
        ``reach_m`` from the edge must be incised (a channel, not a concave slope foot).

    Returns
    -------
    ndarray int64
        Flat indices of the inlet cells, at most one per run of candidates, deepest first.

    Notes
    -----
    O(n) for the edge distance plus O(L) for the candidates' paths (traced together, merging
    where they meet) and O(k·r), vectorised, to follow the k candidates while they stay in
    the patches, r ≈ 4·``reach_m``/``cell_m`` steps at most.
    """
    if patches.shape != valid.shape or depth.shape != valid.shape or (incised is not None and incised.shape != valid.shape):
        raise ValueError("patches, depth, valid and incised must have the same shape")
    if not reach_m > 0:
        raise ValueError(f"reach_m must be > 0, got {reach_m!r}")
    dist = outer_edge_distance(valid).ravel()
    in_patch = ((patches > 0) & valid).ravel()
    reach_cells = reach_m / cell_m
    # candidates: patch cells two cells inside the edge (not next to nodata: an outlet there ends every path),
    # all of them: the deepest may lie beside a nodata notch of a ragged edge, into which it drains
    ring = (in_patch & (dist > 1.5) & (dist <= 2.5)).reshape(valid.shape)
    if not ring.any():
        return np.zeros(0, dtype=np.int64)
    runs, _n = ndimage.label(ring, structure=np.ones((3, 3), dtype=bool))
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
    for _step in range(int(np.ceil(4 * reach_cells)) + 8):  # a path wanders at most ~4x the straight distance
        alive &= in_patch[pos]
        walked += alive
        n_incised += alive & flat_incised[pos]
        reached = alive & (dist[pos] >= reach_cells)
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
        return np.zeros(0, dtype=np.int64)
    # one inlet per run of candidates along the edge: its deepest accepted cell
    lab = runs.ravel()[acc]
    key = np.lexsort((-np.nan_to_num(depth.ravel()[acc], nan=-np.inf), lab))
    first = np.ones(acc.size, dtype=bool)
    first[1:] = lab[key][1:] != lab[key][:-1]
    out = acc[key][first]
    out = out[np.argsort(-np.nan_to_num(depth.ravel()[out], nan=-np.inf), kind="stable")]
    return out.astype(np.int64)
