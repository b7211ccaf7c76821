"""Gullies under shrub crowns: crown mask from the orthophoto, tracing under it, hidden reaches.

On a photogrammetric DSM a gully lined by shrubs is hidden twice. (1) Its floor is raised:
a DSM cell is matched over a window (1 m here), so a cell whose window holds part of a
crown carries the crown's height (foreground fattening of window matching); a 0.7–1.5 m
wide channel between shrubs on both banks reads 0.5–1 m *above* the field beside it, and
steepest descent runs down the field next to the channel. (2) Its incision is gone from the
depth map there, so the map-clipped network drops whatever is traced under the crowns.

The orthophoto shows where the crowns are (foliage is green: excess green, ExG), and the DSM
shows that they stand above the ground. This module makes that *crown mask* (green cells
standing above the ground surface, widened by the matching window), replaces the tracing
surface under it by the harmonic interpolation of the uncontaminated DSM around it (visible
floor between clumps, the gully's up- and downstream reaches, the fields beyond), and marks
traced reaches that run under crowns from one mapped reach to the next (a *hidden reach*,
bridged: it counts as mapped). Config: ``gully.crowns`` (:class:`CrownParams`).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any, Mapping

import cv2
import numpy as np
import scipy.ndimage as ndi
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numba import njit

from kitegully import InputError
from kitegully.gully.network import topological_order

log = logging.getLogger(__name__)

_FOUR = ndi.generate_binary_structure(2, 1)


@dataclass(frozen=True)
class CrownParams:
    """Parameters of the crown mask and the hidden-reach bridges (``gully.crowns``).

    Attributes
    ----------
    enabled : bool
        Trace under crowns and bridge hidden reaches ([I] off by default: see README Stage 6
        for what it does over the ensemble). Needs the orthophoto of the DSM and the
        automatic-head parameters (ground surface and height threshold).
    bins, min_class_fraction, max_valley_ratio : int, float, float
        [P]/[I] The ExG histogram and bimodality tests of the kite-scale OBIA map
        (``obia.threshold``: Mayr et al. 2016's two-peak valley, 256 bins, each side ≥ 1 %,
        valley ≤ 0.9 × the lower peak): foliage is ExG above the valley between the
        soil (and straw) mode and the foliage mode of the orthophoto. No valley: no crowns.
    window_m : float
        [I] The dense-matching window (m; ``dense.matching.window_half_cells`` 2 at 0.2 m:
        5 cells = 1 m). Crown pieces narrower than it are removed (an opening with a disc
        of that diameter: the DSM cannot carry the height of an object smaller than its
        window), and the crowns are widened by it: a DSM cell whose window holds part of a
        crown carries the crown's height (foreground fattening), so every cell within one
        window of a crown is unreliable ground.
    bridge_max_m : float or None
        [I] Longest traced reach under crowns between two mapped reaches that is bridged
        (counts as mapped); ``None`` = no cap: the crowns bound it themselves (every cell of
        a bridged reach lies under the crown mask, so its length is the extent of the
        clumps seen in the orthophoto along the path); 0 = no bridges.
    """

    enabled: bool = False
    bins: int = 256
    min_class_fraction: float = 0.01
    max_valley_ratio: float = 0.9
    window_m: float = 1.0
    bridge_max_m: float | None = None

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any] | None) -> "CrownParams":
        """Build from ``gully.crowns`` (``None`` or missing = disabled)."""
        if not cfg:
            return cls()
        unknown = set(cfg) - set(cls.__dataclass_fields__)
        if unknown:
            raise InputError(f"gully.crowns has unknown key(s) {sorted(unknown)}.")
        p = cls(**{k: cfg[k] for k in cls.__dataclass_fields__ if k in cfg})
        if p.bins < 2 or not 0 <= p.min_class_fraction < 0.5 or p.max_valley_ratio <= 0 or p.window_m < 0 \
                or (p.bridge_max_m is not None and p.bridge_max_m < 0):
            raise InputError("gully.crowns needs bins >= 2, 0 <= min_class_fraction < 0.5, max_valley_ratio > 0, "
                             "window_m >= 0 and bridge_max_m >= 0.")
        return p


def excess_green(rgb: np.ndarray) -> np.ndarray:
    """Excess green 2g − r − b of chromatic coordinates (r = R / (R + G + B) ...), NaN where R + G + B = 0.

    ``rgb`` is (3, H, W) in any linear or gamma-encoded unit (the ratio removes brightness).
    O(n).
    """
    rgb = np.asarray(rgb, dtype=np.float32)
    s = rgb.sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        r, g, b = rgb[0] / s, rgb[1] / s, rgb[2] / s
        exg = 2.0 * g - r - b
    exg[~(s > 0)] = np.nan
    return exg


def green_threshold(exg: np.ndarray, params: CrownParams) -> float | None:
    """ExG threshold of foliage: the valley between the soil mode and the foliage mode, or None.

    The kite-scale OBIA map's rule (:func:`kitegully.obia.threshold.find_thresholds`, Mayr et
    al. 2016: the smoothed histogram reduced to two peaks, valley between them, both sides
    holding ``min_class_fraction`` of the cells and the valley at most ``max_valley_ratio``
    of the lower peak; where that merges grass and shrubs into one mode and fills the valley above
    the soil, the lowest valley of a less smoothed level, session 43). ExG of soil and straw differ by their hue (≈ 0.00–0.06); foliage
    stands at 0.1–0.3, so the camera's colour noise (≈ 0.003 on grey soil) does not set
    the threshold. None when the histogram is not bimodal (no foliage to speak of). O(n).
    """
    from kitegully.obia.threshold import find_thresholds, histogram

    counts, centres = histogram(np.asarray(exg)[np.isfinite(exg)], params.bins)
    res = find_thresholds(counts, centres, params.min_class_fraction, params.max_valley_ratio)
    if not res.bimodal:
        log.info("crown mask: ExG histogram not bimodal (%s): no crowns", res.reason)
        return None
    log.info("crown mask: ExG valley %.4f (%s)", res.valley, res.reason)
    return float(res.valley)


def crown_mask(z: np.ndarray, exg: np.ndarray, ground: np.ndarray, height_threshold_m: float, cell_m: float,
               params: CrownParams) -> tuple[np.ndarray, dict]:
    """Cells whose DSM elevation is a crown's, not the ground's.

    Crowns are green cells (ExG above :func:`green_threshold`) standing more than
    ``height_threshold_m`` above ``ground`` (the ground surface of
    :func:`kitegully.gully.relief.ground_surface`), opened with a disc of diameter
    ``params.window_m`` (pieces the DSM cannot resolve) and widened by ``params.window_m``
    (cells within a matching window of a crown carry its height). Grass is green but lies on
    the ground; bare gully rims stand above the ground surface but are not green. O(n·k) for
    a disc of k cells.

    Parameters
    ----------
    z : ndarray (H, W)
        DSM (m), NaN nodata.
    exg : ndarray (H, W)
        Excess green of the orthophoto on the DSM grid (:func:`excess_green`), NaN unknown.
    ground : ndarray (H, W)
        Ground surface (m), NaN unknown.
    height_threshold_m : float
        Height above ``ground`` (m) a green cell must exceed to be a crown.
    cell_m : float
        Cell size (m).
    params : CrownParams
        ExG histogram tests and matching window.

    Returns
    -------
    mask : ndarray bool (H, W)
    info : dict
        ``green_threshold`` (None: no crowns), ``crown_cells``, ``mask_cells``.
    """
    thr = green_threshold(exg, params)
    if thr is None:
        return np.zeros(np.shape(z), dtype=bool), {"green_threshold": None, "crown_cells": 0, "mask_cells": 0}
    with np.errstate(invalid="ignore"):
        crowns = (exg > thr) & np.isfinite(z) & np.isfinite(ground) & (z - ground > height_threshold_m)
    rad = int(round(0.5 * params.window_m / cell_m))
    if rad > 0 and crowns.any():
        disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * rad + 1, 2 * rad + 1))
        crowns = cv2.morphologyEx(crowns.astype(np.uint8), cv2.MORPH_OPEN, disc).astype(bool)
    mask = crowns
    if params.window_m > 0 and crowns.any():
        dist = cv2.distanceTransform(np.where(crowns, 0, 1).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
        mask = dist * cell_m <= params.window_m
    mask &= np.isfinite(z)
    info = {"green_threshold": thr, "crown_cells": int(crowns.sum()), "mask_cells": int(mask.sum())}
    log.info("crown mask: ExG > %.4f (the histogram's valley) and > %.3f m above the ground, pieces >= %.2f m: %d crown cells, "
             "%d cells (%.2f %%) within %.2f m of them", thr, height_threshold_m, params.window_m, info["crown_cells"],
             info["mask_cells"], 100.0 * info["mask_cells"] / max(1, int(np.isfinite(z).sum())), params.window_m)
    return mask, info


def interpolate_under(z: np.ndarray, mask: np.ndarray, max_unknowns: int = 1_000_000) -> tuple[np.ndarray, int]:
    """``z`` with the cells of ``mask`` replaced by the harmonic interpolation of the cells around them.

    Each masked cell takes the mean of its valid 4-neighbours (masked neighbours unknown,
    unmasked finite ones fixed; NaN or off-grid neighbours are left out, a no-flux edge). A
    masked group with no fixed neighbour keeps its values. Sparse direct solves over whole
    groups, at most ``max_unknowns`` cells per solve (unless one group is larger), about
    O(g^1.5) per compact group of g cells; memory O(max_unknowns) beyond the grids.

    Parameters
    ----------
    z : ndarray (H, W)
        Surface; NaN = no data.
    mask : ndarray (H, W) bool
        Cells to replace.
    max_unknowns : int
        Cells per sparse solve. [I] 1 M keeps SuperLU's factor far below its 32-bit limits
        (one solve over 15 M crown cells at 80 M cells failed; in batches that call peaked at 3.9 GB).

    Returns
    -------
    out : ndarray (H, W) float64
    n : int
        Cells interpolated.
    """
    z = np.asarray(z, dtype=np.float64)
    m_ = np.asarray(mask, dtype=bool) & np.isfinite(z)
    out = z.copy()
    known = np.isfinite(z) & ~m_
    # groups that touch a fixed cell
    lab, n = ndi.label(m_, structure=_FOUR)
    if n == 0:
        return out, 0
    touch = ndi.binary_dilation(known, structure=_FOUR) & m_
    ok = np.zeros(n + 1, dtype=bool)
    ok[np.unique(lab[touch])] = True
    ok[0] = False
    m_ = ok[lab]
    rows, cols = np.nonzero(m_)
    m = rows.size
    if m == 0:
        return out, 0
    # Groups never touch (4-connected labels), so the system is block diagonal: solve it in
    # batches of whole groups. One solve over every crown of a full-size site (15 M unknowns
    # at 80 M cells) overruns SuperLU's 32-bit work arrays (measured: SUPERLU_MALLOC fails).
    order = np.argsort(lab[rows, cols], kind="stable")
    rows, cols = rows[order], cols[order]
    index = np.full(z.shape, -1, dtype=np.int64)
    index[rows, cols] = np.arange(m)
    bounds = np.append(np.flatnonzero(np.diff(lab[rows, cols])) + 1, m)  # where each group ends
    start = 0
    while start < m:
        stop = int(bounds[np.searchsorted(bounds, start + max_unknowns, side="right") - 1])
        if stop <= start:  # one group larger than the cap goes alone
            stop = int(bounds[np.searchsorted(bounds, start, side="right")])
        out[rows[start:stop], cols[start:stop]] = _harmonic_solve(z, known, index, rows[start:stop],
                                                                  cols[start:stop], start)
        start = stop
    return out, m


def _harmonic_solve(z: np.ndarray, known: np.ndarray, index: np.ndarray, rows: np.ndarray, cols: np.ndarray,
                    first: int) -> np.ndarray:
    """Harmonic values of whole masked groups (``index`` numbers them from ``first`` on)."""
    h, w = z.shape
    m = rows.size
    diag = np.zeros(m)
    rhs = np.zeros(m)
    ii, jj = [], []
    for dr, dc in ((-1, 0), (1, 0), (0, -1), (0, 1)):
        nr, nc = rows + dr, cols + dc
        inside = (nr >= 0) & (nr < h) & (nc >= 0) & (nc < w)
        nrc, ncc = np.clip(nr, 0, h - 1), np.clip(nc, 0, w - 1)
        nidx = np.where(inside, index[nrc, ncc], -1)
        fixed = inside & (nidx < 0) & known[nrc, ncc]
        unk = nidx >= 0
        diag += fixed | unk
        rhs[fixed] += z[nrc[fixed], ncc[fixed]]
        ii.append(np.nonzero(unk)[0])
        jj.append(nidx[unk] - first)
    a = sp.csr_matrix((np.concatenate([diag, -np.ones(sum(x.size for x in ii))]),
                       (np.concatenate([np.arange(m), *ii]), np.concatenate([np.arange(m), *jj]))), shape=(m, m))
    return spla.spsolve(a.tocsc(), rhs)


@njit(cache=True)
def _hidden_bridges(cells, pos_down, kept, hidden, width, cell_m, max_m):
    n = cells.size
    order, _ = topological_order(pos_down)  # heads first
    qt = order.size
    step = np.zeros(n)
    for i in range(n):
        j = pos_down[i]
        if j >= 0:
            a = cells[i]
            b = cells[j]
            dr = abs(a // width - b // width)
            dc = abs(a % width - b % width)
            step[i] = cell_m * (1.4142135623730951 if dr + dc == 2 else 1.0)
    inf = np.inf
    up = np.full(n, inf)
    for q in range(qt):  # upstream first: distance from the last mapped cell upstream, through hidden cells
        i = order[q]
        if kept[i]:
            up[i] = 0.0
        j = pos_down[i]
        if j >= 0 and hidden[j] and not kept[j] and (kept[i] or hidden[i]):
            d = up[i] + step[i]
            if d < up[j]:
                up[j] = d
    down = np.full(n, inf)
    for q in range(qt - 1, -1, -1):  # downstream first: distance to the next mapped cell downstream
        i = order[q]
        if kept[i]:
            down[i] = 0.0
        elif hidden[i]:
            j = pos_down[i]
            if j >= 0:
                down[i] = step[i] + down[j]
    out = np.zeros(n, dtype=np.bool_)
    for i in range(n):
        if hidden[i] and not kept[i] and up[i] < inf and down[i] < inf and up[i] + down[i] <= max_m:
            out[i] = True
    return out


def hidden_reaches(cells: np.ndarray, pos_down: np.ndarray, keep: np.ndarray, hidden: np.ndarray, cell_m: float,
                   max_m: float | None) -> np.ndarray:
    """Traced cells of a hidden reach: under crowns all the way from a mapped cell to the next mapped cell downstream.

    Parameters
    ----------
    cells, pos_down : ndarray int64
        The traced network (:class:`kitegully.gully.network.GullyNetwork`).
    keep : ndarray bool (H, W)
        The gully map the network is clipped to.
    hidden : ndarray bool (H, W)
        The crown mask (:func:`crown_mask`).
    cell_m : float
        Cell size (m).
    max_m : float or None
        Longest hidden reach bridged (m), measured along the path from the last mapped cell
        upstream to the first mapped cell downstream; None = no cap.

    Returns
    -------
    ndarray bool (H, W)
        Cells to add to ``keep`` for the mapped network. O(L) for L traced cells.
    """
    shape = keep.shape
    out = np.zeros(shape, dtype=bool)
    max_m = np.inf if max_m is None else float(max_m)
    if cells.size == 0 or max_m <= 0:
        return out
    kept = keep.ravel()[cells]
    hid = hidden.ravel()[cells]
    b = _hidden_bridges(np.asarray(cells, np.int64), np.asarray(pos_down, np.int64), kept, hid, shape[1],
                        float(cell_m), max_m)
    out.ravel()[cells[b]] = True
    return out
