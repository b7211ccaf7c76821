"""Thalweg from the topographic convergence index (Höfle et al. 2013 sect. 4.1).

``TCI = ln(a / tan β)`` with ``a`` the specific catchment area (m²/m) from multiple-flow
routing (Quinn et al. 1991 contour-length weights with Freeman's 1991 slope exponent)
on the priority-flood filled DEM, and ``β`` the local slope of the DEM.
"""

from __future__ import annotations

import logging

import numpy as np
import scipy.ndimage as ndi
import scipy.sparse as sp
import scipy.sparse.linalg as spla
import shapely
from numba import njit
from skimage.morphology import skeletonize

from kitegully import InputError
from kitegully.io.raster import GridSpec
from kitegully.polygons.skeleton import remove_short_components, skeleton_paths
from kitegully.terrain.fill import priority_flood_fill
from kitegully.terrain.flow import D8_OFFSETS, NO_FLOW, d8_directions

log = logging.getLogger(__name__)

_DR = np.array([-1, -1, -1, 0, 0, 1, 1, 1])
_DC = np.array([-1, 0, 1, -1, 1, -1, 0, 1])


@njit(cache=True)
def _mfd(z, order, cell, exponent, acc):
    h, w = z.shape
    dist = np.empty(8)
    clen = np.empty(8)
    for k in range(8):
        diag = _DR[k] != 0 and _DC[k] != 0
        dist[k] = cell * (np.sqrt(2.0) if diag else 1.0)
        clen[k] = cell * (0.354 if diag else 0.5)  # Quinn et al. 1991 contour lengths
    wts = np.empty(8)
    for i in range(order.size):
        j = order[i]
        r = j // w
        c = j % w
        zc = z[r, c]
        tot = 0.0
        for k in range(8):
            rr = r + _DR[k]
            cc = c + _DC[k]
            wts[k] = 0.0
            if rr < 0 or rr >= h or cc < 0 or cc >= w:
                continue
            zn = z[rr, cc]
            if not np.isfinite(zn) or zn >= zc:
                continue
            wts[k] = ((zc - zn) / dist[k]) ** exponent * clen[k]
            tot += wts[k]
        if tot <= 0.0:
            continue
        a = acc[r, c]
        for k in range(8):
            if wts[k] > 0.0:
                acc[r + _DR[k], c + _DC[k]] += a * wts[k] / tot


def mfd_catchment_area(z: np.ndarray, cell: float, exponent: float = 1.1, epsilon: float = 1e-4) -> np.ndarray:
    """Upslope area (m²) by multiple-flow-direction routing on the filled DEM.

    Parameters
    ----------
    z : ndarray (H, W)
        DEM (m), NaN nodata (flow leaves the grid there).
    cell : float
        Cell size (m).
    exponent : float
        Slope exponent of the flow partition (Freeman 1991: 1.1; Quinn 1991: 1).
    epsilon : float
        Priority-flood gradient (m per cell) so that every cell drains.

    Returns
    -------
    ndarray float64
        Contributing area (m²), including the cell itself; NaN where ``z`` is NaN.

    Notes
    -----
    Cells are processed from high to low (one sort), each passing its area to its lower
    neighbours in proportion to ``(tan β_k)^p · L_k``. O(n log n) time, O(n) memory.
    """
    filled, _ = priority_flood_fill(z, epsilon=epsilon)
    valid = np.isfinite(filled)
    flat = np.where(valid, filled, -np.inf).ravel()
    order = np.argsort(-flat, kind="stable")
    order = order[: int(valid.sum())]
    acc = np.where(valid, cell * cell, 0.0)
    _mfd(np.where(valid, filled, np.nan), order.astype(np.int64), float(cell), float(exponent), acc)
    acc[~valid] = np.nan
    return acc


def local_slope(z: np.ndarray, cell: float) -> np.ndarray:
    """tan β from Horn's 3 × 3 finite differences (NaN next to nodata)."""
    zp = np.pad(np.asarray(z, np.float64), 1, mode="edge")
    a, b, c = zp[:-2, :-2], zp[:-2, 1:-1], zp[:-2, 2:]
    d, f = zp[1:-1, :-2], zp[1:-1, 2:]
    g, hh, i = zp[2:, :-2], zp[2:, 1:-1], zp[2:, 2:]
    dzdx = ((c + 2 * f + i) - (a + 2 * d + g)) / (8 * cell)
    dzdy = ((g + 2 * hh + i) - (a + 2 * b + c)) / (8 * cell)
    return np.hypot(dzdx, dzdy)


def topographic_convergence_index(z: np.ndarray, cell: float, exponent: float, min_tan_slope: float) -> tuple[np.ndarray, np.ndarray]:
    """TCI = ln(a / tan β), with a = MFD area / cell width (m²/m) and tan β ≥ ``min_tan_slope``.

    Returns (tci, specific catchment area).

    Parameters
    ----------
    z : ndarray (H, W)
        DEM (m), NaN nodata.
    cell : float
        Cell size (m).
    exponent : float
        Slope exponent of the flow partition (:func:`mfd_catchment_area`).
    min_tan_slope : float
        Smallest tan β used.

    Returns
    -------
    tci : ndarray (H, W) float32
        Topographic convergence index.
    sca : ndarray (H, W) float32
        Specific catchment area (m²/m).
    """
    area = mfd_catchment_area(z, cell, exponent)
    sca = area / cell
    tanb = np.maximum(local_slope(z, cell), min_tan_slope)
    with np.errstate(invalid="ignore", divide="ignore"):
        tci = np.log(sca / tanb)
    return tci.astype(np.float32), sca.astype(np.float32)


def snakes_smooth(xy: np.ndarray, alpha: float = 1.0, beta: float = 1.0) -> np.ndarray:
    """Snakes line smoothing (GRASS ``v.generalize method=snakes``), end points kept.

    Minimises ``Σ |x_i - x⁰_i|² + α |x''_i|² + β |x''''_i|²`` (second and fourth
    differences of the vertex sequence): ``(I + α D2ᵀD2 + β D4ᵀD4) x = x⁰``.

    Parameters
    ----------
    xy : ndarray (n, 2)
        Vertices of the line.
    alpha, beta : float
        Weights of the second and fourth differences.

    Returns
    -------
    ndarray (n, 2)
        Smoothed vertices; a copy of ``xy`` for fewer than 5 vertices.
    """
    n = len(xy)
    if n < 5:
        return xy.copy()
    d2 = sp.diags([1.0, -2.0, 1.0], [0, 1, 2], shape=(n - 2, n))
    d4 = sp.diags([1.0, -4.0, 6.0, -4.0, 1.0], [0, 1, 2, 3, 4], shape=(n - 4, n))
    A = (sp.identity(n) + alpha * (d2.T @ d2) + beta * (d4.T @ d4)).tolil()
    rhs = xy.astype(np.float64).copy()
    for i in (0, n - 1):  # fixed end points
        A[i, :] = 0.0
        A[i, i] = 1.0
    return spla.spsolve(A.tocsc(), rhs)


def resample_line(xy: np.ndarray, step: float) -> np.ndarray:
    """Vertices every ``step`` metres along a polyline (end point kept)."""
    seg = np.hypot(*np.diff(xy, axis=0).T)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    if s[-1] <= 0:
        return xy[:1]
    n = max(int(np.ceil(s[-1] / step)), 1)
    t = np.linspace(0.0, s[-1], n + 1)
    return np.column_stack([np.interp(t, s, xy[:, 0]), np.interp(t, s, xy[:, 1])])


def incised_cells(dem: np.ndarray, cell: float, min_incision_m: float, window_m: float,
                  ground_window_m: float | None = None) -> np.ndarray:
    """Cells lying at least ``min_incision_m`` below the mean surface within a square of side ``window_m``.

    Parameters
    ----------
    dem : ndarray (H, W)
        Elevations (m), NaN = nodata (replaced by the DEM's mean, never incised).
    cell : float
        Cell size (m).
    min_incision_m, window_m : float
        Depth below the window's mean (m) and the window's side (m).
    ground_window_m : float, optional
        Compare the ground surface instead of the DEM: a grey opening over a square of this
        side (m, rounded to an odd number of cells), which removes crowns and hedges narrower than it and keeps channels
        (pits). On a DSM the crowns in the window raise its mean, and open ground beside a
        tree row would pass as incised.

    Returns
    -------
    ndarray of bool (H, W)

    Notes
    -----
    O(n) (separable box and min/max filters).
    """
    ok = np.isfinite(dem)
    zf = np.where(ok, dem, np.nanmean(dem)).astype(np.float64)
    if ground_window_m is not None:
        k = max(3, int(round(ground_window_m / cell)) | 1)
        zf = ndi.grey_opening(zf, size=(k, k), mode="nearest")
    size = max(3, int(round(window_m / cell)) | 1)
    return ok & (zf - ndi.uniform_filter(zf, size=size, mode="nearest") <= -min_incision_m)


@njit(cache=True)
def _follow_flow(dirs, incised, seeds, gap, offs):
    h, w = dirs.shape
    d = dirs.ravel()
    inc = incised.ravel()
    out = seeds.ravel().copy()
    pend = np.empty(gap + 1, dtype=np.int64)
    for i in np.flatnonzero(seeds.ravel()):
        j = i
        npend = 0
        while True:
            k = d[j]
            if k == NO_FLOW:
                break
            r = j // w
            j = (r + offs[k, 0]) * w + (j - r * w) + offs[k, 1]
            if out[j] or inc[j]:
                for q in range(npend):
                    out[pend[q]] = True
                npend = 0
                if out[j]:
                    break  # joined cells whose own path goes on downstream
                out[j] = True
            else:
                if npend == gap:
                    break
                pend[npend] = j
                npend += 1
    return out.reshape(h, w)


def follow_flow(seeds: np.ndarray, incised: np.ndarray, dem: np.ndarray, gap_cells: int) -> np.ndarray:
    """Extend a channel mask down the D8 steepest-descent paths while they run through incised ground.

    From every ``seeds`` cell the flow path of the priority-flood-filled ``dem`` is followed
    downstream; its cells join the mask while they are ``incised``. A stretch of at most
    ``gap_cells`` non-incised cells is bridged when incised ground (or the mask) follows; a
    longer one ends the path, as do nodata and the grid edge. Flow is never followed upslope.

    Parameters
    ----------
    seeds : ndarray of bool (H, W)
        The channel cells to start from (e.g. high TCI and incised).
    incised : ndarray of bool (H, W)
        Cells a channel may run through.
    dem : ndarray (H, W)
        Elevations (m), NaN = nodata.
    gap_cells : int
        Longest non-incised stretch bridged (cells, ≥ 0).

    Returns
    -------
    ndarray of bool (H, W)
        ``seeds`` and the path cells added.

    Notes
    -----
    O(n log n) for the fill, then O(seeds · gap_cells + added cells): a path stops at the
    first cell already in the mask, whose own path goes on from there.
    """
    filled, _ = priority_flood_fill(np.asarray(dem, dtype=np.float64))
    dirs = d8_directions(filled)
    return _follow_flow(dirs, np.ascontiguousarray(incised, dtype=np.bool_), np.ascontiguousarray(seeds, dtype=np.bool_),
                        int(max(gap_cells, 0)), D8_OFFSETS)


def thalweg_lines(
    tci: np.ndarray,
    grid: GridSpec,
    threshold: float,
    min_length_m: float,
    smooth_step_m: float,
    alpha: float,
    beta: float,
    dem: np.ndarray | None = None,
    min_incision_m: float | None = None,
    incision_window_m: float = 30.0,
    closing_cells: int = 1,
    follow_flow_downstream: bool = False,
    ground_window_m: float | None = None,
) -> tuple[list[shapely.LineString], np.ndarray]:
    """Mask TCI > threshold, skeletonise, vectorise, drop short pieces, smooth with snakes.

    With ``min_incision_m``, only cells at least that far below the mean of the DEM in a
    square of side ``incision_window_m`` around them stay in the mask: a channel is incised,
    a flat valley floor (high TCI because tan β is small) is not. With ``ground_window_m``
    the rule compares the ground surface, a grey opening of the DEM over a square of that
    side (m; crowns and hedges narrower than it removed, channels kept), with its own mean:
    on a DSM the crowns in the window would raise the mean and make fields beside them
    "incised" (:func:`incised_cells`). A closing with a
    ``closing_cells`` square then joins the fragments that flow braiding across a wide,
    rough channel floor leaves. With ``follow_flow_downstream`` (and ``min_incision_m``), the
    mask is first extended down the flow paths through incised cells (:func:`follow_flow`,
    stretches up to ``closing_cells`` bridged): the floor of a deep reach, whose walls raise its
    local slope and lower its TCI, joins the high-TCI fragments above it.

    Returns the smoothed lines (map coordinates) and the raster of their skeleton cells.
    Raises :class:`InputError` when no line is left.

    Parameters
    ----------
    tci : ndarray (H, W)
        Topographic convergence index, NaN read as below the threshold.
    grid : GridSpec
        Grid of ``tci``.
    threshold : float
        TCI threshold.
    min_length_m : float
        Shortest line kept (m).
    smooth_step_m : float
        Vertex spacing before smoothing (m).
    alpha, beta : float
        Snakes weights (:func:`snakes_smooth`).
    dem : ndarray (H, W) or None
        DEM (m) for the incision test.
    min_incision_m : float or None
        Least depth below the window's mean (m); None = no incision test.
    incision_window_m : float
        Side of the square window (m).
    closing_cells : int
        Side of the closing square (cells), also the longest gap bridged when following the flow.
    follow_flow_downstream : bool
        Extend the mask down the flow paths through incised cells.
    ground_window_m : float or None
        Side of the grey opening for the ground surface (m); None = the DEM as it is.

    Returns
    -------
    lines : list of LineString
        Smoothed thalweg lines (map coordinates).
    cells : ndarray (H, W) bool
        Skeleton cells of the kept lines.
    """
    mask = np.nan_to_num(tci, nan=-np.inf) > threshold
    if min_incision_m is not None and dem is not None:
        n_before = int(mask.sum())
        incised = incised_cells(dem, grid.cell, min_incision_m, incision_window_m, ground_window_m)
        mask &= incised
        log.info("thalweg: %d of %d cells with TCI > %.3g are incised >= %.2f m below the %.0f m mean", int(mask.sum()), n_before,
                 threshold, min_incision_m, incision_window_m)
        if follow_flow_downstream:
            n_seed = int(mask.sum())
            mask = follow_flow(mask, incised, dem, closing_cells)
            log.info("thalweg: flow followed downstream through incised ground: %d cells added to %d", int(mask.sum()) - n_seed, n_seed)
    if closing_cells > 1:
        pad = closing_cells
        mask = ndi.binary_closing(np.pad(mask, pad), structure=np.ones((closing_cells, closing_cells), bool))[pad:-pad, pad:-pad]
    n_min = max(2, int(np.ceil(min_length_m / grid.cell)))
    mask = remove_short_components(mask, n_min)
    skel = skeletonize(mask)
    xs, ys = grid.cell_centres()
    lines = []
    kept = np.zeros_like(skel)
    for r, c in skeleton_paths(skel, min_cells=2):
        xy = np.column_stack([xs[c], ys[r]])
        length = float(np.sum(np.hypot(*np.diff(xy, axis=0).T)))
        if length < min_length_m:
            continue
        kept[r, c] = True
        xy = snakes_smooth(resample_line(xy, smooth_step_m), alpha, beta)
        lines.append(shapely.LineString(xy))
    log.info("thalweg: %.2f %% of cells with TCI > %.3g, %d lines >= %.1f m (total %.0f m)",
             100.0 * mask.mean(), threshold, len(lines), min_length_m, sum(l.length for l in lines))
    if not lines:
        raise InputError(f"polygons.thalweg.tci_threshold: no thalweg found: no cells with TCI > {threshold} form a line of at least {min_length_m} m")
    return lines, kept
