"""Headcut retreat per digitised head, measured on the two DEMs along the epoch-1 thalweg.

Model ([I], issue 17 session 6). A head is where the channel's incision begins: along the
thalweg the incision depth rises from the hillslope level ``D_top`` (≈ 0) to the channel's
``D_bot`` over a head ramp of length L (L ≈ 0 for a vertical headwall, L = the retreat for a
head that was cut back as a wedge). A DEM made by dense matching sees this profile
convolved with its matching window of width w (a symmetric kernel):

* the half-height point (depth = ``D_top + ½ (D_bot − D_top)``) of a step or of any ramp
  symmetric about its centre does not move under a symmetric kernel; the foot and top
  points of a step move by ± w/2;
* a linear ramp longer than w is unchanged by the kernel except at its two rounded
  corners, so the straight line through its 25 % and 75 % crossings, extrapolated to
  ``D_top``, still meets the hillslope at the lip (where the incision begins); for a step
  the same line meets it w/2 upslope of the step, the same offset at both epochs, which
  cancels in the retreat.

Session 8: the two points above assume the head keeps its shape. It does not: a headwall at
epoch 1 (L ≈ 0) is, on the twin, a wedge of length L = r at epoch 2 (the retreated head's
depth rises linearly over the retreat), so the extrapolated line put epoch 1's lip w/2 upslope
of the wall but epoch 2's at the wedge's tip, and measured r − w/2. The stated head of each
epoch is now the lip of the **fitted smoothed head model** (:func:`fit_head`): hillslope level,
linear ramp of length L ≥ 0 from the lip, channel level, smoothed by a box of w; least squares
over lip and L, the lip tried at most ``max_retreat_m + window_m`` upslope of the epoch-1
channel's coarse head (farther upslope lie other hollows and shrubs that the former 10 m
profile let the crossings lock on). The retreat is lip₁ − lip₂ along the epoch-1 downstream
axis (upslope positive, signed: a negative value on a stable head is measurement noise, kept
so its spread stays visible).
The half-height retreat (``retreat_mid_m``, level crossings as below) and the older estimate, the upslope reach of
significant DoD lowering from the epoch-1 head (``retreat_dod_m``), are reported beside it.

Steps per head: (1) on epoch 1's ground surface (grey opening over ``object_window_m``: shrub
crowns narrower than the window are removed, channels, being pits, are kept), cells incised
more than ``min_incision_m`` below a Gaussian-smoothed surface (σ = ``incision_sigma_m``) are
channel; the piece nearest the digitised point within ``search_radius_m`` is this gully and
its highest cell the coarse head; the mean of the piece's cells within ``window_m`` of it is
the profile origin, and the direction from there to the mean of its cells within
``axis_length_m`` the downstream axis. (2) Along that axis, from
``search_radius_m`` upslope to ``window_m + 1.5 m`` downstream, each DEM's depth profile is
the bank level (median ground elevation ``window_m`` to ``2·window_m`` beyond the thalweg band
on both sides, averaged) minus the thalweg (the lowest DEM elevation within
``thalweg_halfwidth_m`` of the axis). (3) ``D_bot`` = median depth from ``window_m`` to
``window_m + 1.5 m`` downstream of the coarse head (the smoothed step has reached full depth
there); walking upslope, a crossing of a level is the first station below it that stays
below it over half a window; ``D_top`` = median depth one to three windows upslope of the
half-height crossing (two passes, the first with ``D_top`` = 0).
"""

from __future__ import annotations

import logging
import warnings

from typing import Mapping

import numpy as np
import pandas as pd
from scipy import ndimage

from kitegully.change.params import ChangeParams
from kitegully.io.raster import GridSpec

log = logging.getLogger(__name__)

#: Columns of the headcut table.
COLUMNS = ["head_id", "x_digitised", "y_digitised", "x1", "y1", "incision1_m", "x2", "y2", "incision2_m", "axis_x", "axis_y",
           "retreat_m", "retreat_mid_m", "retreat_dod_m"]

_PLATEAU_M = 1.5  # [I] length of the stretch whose median is the channel depth D_bot (several windows' worth of stations)


def _smooth_nan(z: np.ndarray, sigma_cells: float) -> np.ndarray:
    ok = np.isfinite(z)
    num = ndimage.gaussian_filter(np.where(ok, z, 0.0), sigma_cells, mode="nearest")
    den = ndimage.gaussian_filter(ok.astype(np.float64), sigma_cells, mode="nearest")
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0.05, num / den, np.nan)


def ground_surface(z: np.ndarray, window_cells: int) -> np.ndarray:
    """Grey opening of ``z`` over a square of ``window_cells``: objects narrower than it (shrubs) removed, pits kept.

    NaN stays NaN. O(cells · window).
    """
    ok = np.isfinite(z)
    if not ok.any():
        return np.full(z.shape, np.nan)
    zf = np.where(ok, z, np.nanmax(z))
    return np.where(ok, ndimage.grey_opening(zf, size=(window_cells, window_cells)), np.nan)


def _window(grid: GridSpec, x: float, y: float, pad: int) -> tuple[int, int, int, int, float, float]:
    r0f, c0f = (float(v[0]) for v in grid.rowcol(np.array([x]), np.array([y])))
    r0, c0 = int(round(r0f)), int(round(c0f))
    return max(r0 - pad, 0), min(r0 + pad + 1, grid.height), max(c0 - pad, 0), min(c0 + pad + 1, grid.width), r0f, c0f


def locate_channel(z: np.ndarray, grid: GridSpec, x: float, y: float, params: ChangeParams) -> tuple[float, float, float, float] | None:
    """Coarse head (x, y) and unit downstream axis (tx, ty) of the channel nearest (x, y) on DEM ``z``; None if none.

    Works on a window of radius + 4σ around the point: O(window cells · object window).

    Parameters
    ----------
    z : ndarray (H, W)
        The DEM on ``grid`` (m).
    grid : GridSpec
        Grid of ``z``.
    x, y : float
        The digitised head (m, grid CRS).
    params : ChangeParams
        ``headcut_*`` keys and ``stable_object_window_m`` (the ground surface's window).

    Returns
    -------
    tuple of float or None
        ``(x, y, tx, ty)``: the coarse head (m) and the unit downstream axis; None when no channel is found or
        its axis is too short.
    """
    c = grid.cell
    rad = params.headcut_search_radius_m / c
    sig = params.headcut_incision_sigma_m / c
    ra, rb, ca, cb, r0f, c0f = _window(grid, x, y, int(np.ceil(rad + 4 * sig)))
    if ra >= rb or ca >= cb:
        return None
    win = z[ra:rb, ca:cb].astype(np.float64)
    G = ground_surface(win, max(3, int(round(params.stable_object_window_m / c)) | 1))
    depth = _smooth_nan(G, sig) - G
    rr, cc = np.mgrid[ra:rb, ca:cb]
    dist = np.hypot(rr - r0f, cc - c0f)
    chan = (dist <= rad) & (depth > params.headcut_min_incision_m)
    if not chan.any():
        return None
    lab, _ = ndimage.label(chan, structure=np.ones((3, 3)))
    piece = lab == lab.ravel()[int(np.argmin(np.where(chan, dist, np.inf)))]
    k = int(np.nanargmax(np.where(piece, G, -np.inf)))
    hr, hc = np.unravel_index(k, win.shape)
    dh = np.hypot(rr - (ra + hr), cc - (ca + hc)) * c
    near = piece & (dh <= params.headcut_axis_length_m)
    top = piece & (dh <= params.headcut_window_m)
    # origin: the mean of the channel cells within a window of the highest one (the channel's
    # centre near its head, not a corner cell); axis: from there to the mean of the cells within
    # axis_length_m (points downstream whatever the channel's width; a principal axis does not
    # where the piece near the head is a blob, e.g. at a junction)
    ox, oy = float(np.mean(cc[top])), float(-np.mean(rr[top]))
    v = np.array([float(np.mean(cc[near])) - ox, float(-np.mean(rr[near])) - oy])
    n = float(np.hypot(*v))
    if n < 0.5 * params.headcut_window_m / c:
        return None
    hx, hy = grid.xy(-oy, ox)
    return float(hx), float(hy), float(v[0] / n), float(v[1] / n)


def depth_profile(z: np.ndarray, ground: np.ndarray, grid: GridSpec, origin: tuple[int, int], x0: float, y0: float,
                  t: np.ndarray, s: np.ndarray, params: ChangeParams) -> np.ndarray:
    """Incision depth (m) at stations ``s`` (m, downstream positive) along the axis ``t`` through (x0, y0).

    ``z`` and ``ground`` are windows of the DEM and its ground surface whose first cell is
    ``origin`` (row, col) of ``grid``. Bank level (median of the ground ``window_m`` to
    ``2·window_m`` beyond the thalweg band, mean of both sides) minus the thalweg (lowest
    DEM elevation within ``thalweg_halfwidth_m``). Bilinear sampling every half cell across.

    Parameters
    ----------
    z, ground : ndarray
        Windows of the DEM and of its ground surface (m).
    grid : GridSpec
        The whole grid.
    origin : tuple of int
        ``(row, col)`` of the windows' first cell on ``grid``.
    x0, y0 : float
        The axis point at station 0 (m).
    t : ndarray (2,)
        Unit downstream axis (x, y).
    s : ndarray
        Stations (m, downstream positive).
    params : ChangeParams
        Reads ``headcut_thalweg_halfwidth_m`` and ``headcut_window_m``.

    Returns
    -------
    ndarray
        Depth at each station (m); NaN where the samples are all NaN.
    """
    du = grid.cell / 2
    a, w = params.headcut_thalweg_halfwidth_m, params.headcut_window_m
    nrm = np.array([-t[1], t[0]])

    def sample(arr, u):
        S, U = np.meshgrid(s, u, indexing="ij")
        r, c = grid.rowcol(x0 + S * t[0] + U * nrm[0], y0 + S * t[1] + U * nrm[1])
        v = ndimage.map_coordinates(arr, [r.ravel() - origin[0], c.ravel() - origin[1]], order=1, mode="constant",
                                    cval=np.nan, prefilter=False)
        return v.reshape(S.shape)

    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN stations (voids) stay NaN
        thal = np.nanmin(sample(z, np.arange(-a, a + 1e-9, du)), axis=1)
        ub = np.arange(a + w, a + 2 * w + 1e-9, du)
        banks = np.vstack([np.nanmedian(sample(ground, sgn * ub), axis=1) for sgn in (1.0, -1.0)])
        return np.nanmean(banks, axis=0) - thal


def _crossing(s: np.ndarray, d: np.ndarray, i0: int, level: float, run: int) -> float:
    """Walking upslope from station ``i0``: where ``d`` falls below ``level`` and stays below over ``run`` stations.

    Linear interpolation between the first such station and the nearest station downstream
    of it at or above the level (sub-station precision). NaN when there is none.
    """
    for i in range(min(i0, len(s) - 1), run - 1, -1):
        if not (np.isfinite(d[i]) and d[i] < level):
            continue
        stretch = d[i - run + 1:i + 1]
        if np.nanmedian(stretch) >= level:
            continue
        k = i + 1
        while k < len(s) and not (np.isfinite(d[k]) and d[k] >= level):
            k += 1
        if k >= len(s):
            return np.nan
        j = k - 1 if np.isfinite(d[k - 1]) else i
        return float(s[j] + (level - d[j]) / (d[k] - d[j]) * (s[k] - s[j]))
    return np.nan


def _blurred_ramps(s: np.ndarray, lips: np.ndarray, lengths: np.ndarray, window_m: float) -> np.ndarray:
    """Unit head ramps (0 upslope of the lip, 1 from lip + L on) smoothed by a box of ``window_m``, on stations ``s``.

    Returns an array (len(lengths), len(lips), len(s)). L = 0 is a step. O(L · lips · stations).
    """
    step = float(s[1] - s[0])
    x = s[None, None, :] - lips[None, :, None]
    L = lengths[:, None, None]
    with np.errstate(invalid="ignore", divide="ignore"):
        f = np.where(L > 0, np.clip(x / np.where(L > 0, L, 1.0), 0.0, 1.0), (x >= 0).astype(np.float64))
    k = max(1, int(round(window_m / step)))
    return ndimage.uniform_filter1d(f, k, axis=-1, mode="nearest") if k > 1 else f


def fit_head(s: np.ndarray, d: np.ndarray, params: ChangeParams) -> dict[str, float]:
    """Lip, ramp length, ``D_top`` and ``D_bot`` of the head model that best fits a depth profile (least squares).

    Model ([I], session 8): the incision depth is ``D_top`` upslope of the lip, rises linearly
    over a ramp of length L ≥ 0 (L ≈ 0: a headwall; L = the retreat: a head cut back as a
    wedge) and stays at ``D_bot`` downstream, all smoothed by the DEM's horizontal resolution
    (a box of ``window_m``, the dense-matching window). Fitting the smoothed model puts the lip
    where the incision begins for a step and for a ramp alike, so a head that changes shape
    between epochs (a step at epoch 1, a wedge at epoch 2) is not biased by w/2 as the
    extrapolated 25-75 % line is. Lips are tried every profile station from
    ``max_retreat_m + window_m`` upslope of the coarse head (the farthest a head can have moved
    in one season, plus the smoothing) to ``window_m`` short of the profile's end; ramp lengths
    from 0 to that same distance in profile steps; the fit uses the stations from three windows
    upslope of the first lip tried (the hillslope level) to the end. ``D_top``, ``D_bot`` solve a
    linear least-squares problem per (lip, L); only D_bot > D_top counts. NaN where no
    finite fit exists; ``rms`` is the fit's residual RMS (see :func:`head_observed`).
    O(lips · lengths · stations).

    Parameters
    ----------
    s : ndarray
        Evenly spaced stations (m, downstream positive, 0 at the coarse head).
    d : ndarray
        Incision depth at each station (m); NaN stations are left out of the fit.
    params : ChangeParams
        Reads ``headcut_window_m`` and ``headcut_max_retreat_m``.

    Returns
    -------
    dict
        ``lip`` (station, m), ``length`` (ramp length, m), ``top`` and ``bottom`` (``D_top``, ``D_bot``, m) and
        ``rms`` (m).
    """
    w, step = params.headcut_window_m, float(s[1] - s[0])
    reach = params.headcut_max_retreat_m + w
    out = dict(lip=np.nan, length=np.nan, top=np.nan, bottom=np.nan, rms=np.nan)
    use = np.isfinite(d) & (s >= -reach - 3 * w)
    lips = s[(s >= -reach - 1e-9) & (s <= s[-1] - w)]
    if use.sum() < 4 or lips.size == 0:
        return out
    lengths = np.arange(0.0, reach + 1e-9, step)
    f = _blurred_ramps(s, lips, lengths, w)[..., use]
    y = d[use]
    fm = f.mean(axis=-1)
    cov = ((f - fm[..., None]) * (y - y.mean())).sum(axis=-1)
    var = ((f - fm[..., None]) ** 2).sum(axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        rise = cov / var  # D_bot − D_top
        sse = ((y - y.mean()) ** 2).sum() - cov * rise
    sse = np.where(np.isfinite(rise) & (rise > 0) & (var > 1e-9), sse, np.inf)
    if not np.isfinite(sse).any():
        return out
    il, jl = np.unravel_index(int(np.argmin(sse)), sse.shape)
    top = float(y.mean() - rise[il, jl] * fm[il, jl])
    rms = float(np.sqrt(max(float(sse[il, jl]), 0.0) / y.size))
    return dict(lip=float(lips[jl]), length=float(lengths[il]), top=top, bottom=top + float(rise[il, jl]), rms=rms)


def head_observed(s: np.ndarray, d: np.ndarray, fit: Mapping[str, float], params: ChangeParams) -> bool:
    """Whether a fitted lip is a measurement ([I], session 8): the fit rises, and the lip lies on observed ground.

    Every station within ``window_m`` of the lip must hold a value: the smoothing window's
    worth of profile on each side is what places a lip, and a lip on the edge of or inside a
    void (DSM edge, no match) is placed by the model alone. (A stricter gate, rise ≥ 1.96 ×
    the fit's residual RMS, was tried on the default twin: it dropped 8 of 15 stable heads
    and no moving one; not adopted.)

    Parameters
    ----------
    s : ndarray
        Stations of the profile (m, downstream positive).
    d : ndarray
        Incision depth at each station (m).
    fit : mapping
        :func:`fit_head`'s result (``lip``, ``top``, ``bottom``).
    params : ChangeParams
        Reads ``headcut_window_m``.

    Returns
    -------
    bool
        True when the lip is a measurement.
    """
    if not np.isfinite(fit.get("lip", np.nan)):
        return False
    near = np.abs(s - fit["lip"]) <= params.headcut_window_m
    return bool(fit["bottom"] > fit["top"] and np.isfinite(d[near]).all())


def locate_head(s: np.ndarray, d: np.ndarray, params: ChangeParams) -> dict[str, float]:
    """Lip (fitted head model, :func:`fit_head`), half-height point, ``D_top`` and ``D_bot`` of the head on a depth profile.

    ``s`` must start upslope (negative) and reach ``window_m + 1.5 m`` downstream of 0 (the
    coarse head). The half-height point is found by the level crossings of the module
    docstring (its own ``D_top``/``D_bot``, reported beside the lip); ``top``/``bottom`` are
    the fitted levels. The lip is NaN where there is no fit or it fails :func:`head_observed`;
    the half-height point is NaN where there is no crossing.

    Parameters
    ----------
    s : ndarray
        Evenly spaced stations (m, downstream positive, 0 at the coarse head).
    d : ndarray
        Incision depth at each station (m).
    params : ChangeParams
        Reads ``headcut_window_m`` and ``headcut_max_retreat_m``.

    Returns
    -------
    dict
        ``lip`` and ``mid`` (stations, m), ``top`` and ``bottom`` (fitted levels, m).
    """
    w = params.headcut_window_m
    step = float(s[1] - s[0])
    run = max(1, int(round(0.5 * w / step)))
    i0 = int(np.searchsorted(s, w))
    bot = (s >= w) & (s <= w + _PLATEAU_M)
    fit = fit_head(s, d, params)
    out = dict(lip=fit["lip"] if head_observed(s, d, fit, params) else np.nan, mid=np.nan, top=fit["top"], bottom=fit["bottom"])
    if not np.any(np.isfinite(d[bot])):
        return out
    Db = float(np.nanmedian(d[bot]))
    Dt = 0.0
    for _ in range(2):
        mid = _crossing(s, d, i0, Dt + 0.5 * (Db - Dt), run)
        if not np.isfinite(mid) or Db <= Dt:
            return out
        up = (s >= mid - 3 * w) & (s <= mid - w)
        Dt = float(np.nanmedian(d[up])) if np.any(np.isfinite(d[up])) else 0.0
    return dict(out, mid=_crossing(s, d, i0, Dt + 0.5 * (Db - Dt), run))


def dod_reach(dod: np.ndarray, grid: GridSpec, x1: float, y1: float, up: np.ndarray, radius_m: float,
              lowering_m: float, touch_m: float) -> float:
    """Upslope reach (m) of the significant-lowering piece touching (x1, y1); 0 when none touches (the pre-session-6 estimate).

    Parameters
    ----------
    dod : ndarray (H, W)
        DoD on ``grid`` (m).
    grid : GridSpec
        Grid of ``dod``.
    x1, y1 : float
        The epoch-1 head (m).
    up : ndarray (2,)
        Unit upslope axis (x, y).
    radius_m : float
        Search radius around the head (m).
    lowering_m : float
        Significant lowering (m): cells with DoD below ``-lowering_m``.
    touch_m : float
        A piece with a cell this close to the head (m) touches it.

    Returns
    -------
    float
        The reach (m), at least 0.
    """
    c = grid.cell

    ra, rb, ca, cb, r0f, c0f = _window(grid, x1, y1, int(np.ceil(radius_m / c)))
    win = dod[ra:rb, ca:cb]
    rr, cc = np.mgrid[ra:rb, ca:cb]
    dist = np.hypot(rr - r0f, cc - c0f) * c
    low = (dist <= radius_m) & (win < -lowering_m)
    if not low.any():
        return 0.0
    lab, _ = ndimage.label(low, structure=np.ones((3, 3)))
    touching = np.unique(lab[low & (dist <= touch_m)])
    if touching.size == 0:
        return 0.0
    piece = np.isin(lab, touching)
    px = (cc[piece] - c0f) * c
    py = -(rr[piece] - r0f) * c
    return float(max(0.0, np.max(px * up[0] + py * up[1])))


def measure_headcut_retreat(z1: np.ndarray, z2: np.ndarray, grid: GridSpec, heads: pd.DataFrame,
                            params: ChangeParams, lowering_m: float | None = None) -> pd.DataFrame:
    """Head (lip) position on each DEM and the retreat between them, per digitised head.

    Parameters
    ----------
    z1, z2 : ndarray (H, W)
        Epoch-1 and co-registered epoch-2 DEMs on ``grid``.
    heads : DataFrame
        ``head_id, x, y`` of the heads digitised at epoch 1.
    params : ChangeParams
        ``headcut_*`` keys and ``stable_object_window_m`` (the ground surface's window).
    lowering_m : float, optional
        Significant lowering of the DoD-reach estimate (m); default ``min_incision_m``.

    Returns
    -------
    DataFrame
        :data:`COLUMNS`: ``x1, y1`` / ``x2, y2`` the lips on the epoch-1 axis, ``incision*_m``
        the channel depth below the hillslope level (D_bot − D_top), ``axis_x, axis_y`` the
        downstream unit axis, ``retreat_m`` (stated: lip₁ − lip₂, m, upslope positive),
        ``retreat_mid_m`` (half-height points) and ``retreat_dod_m`` (DoD reach).

    Notes
    -----
    O(heads · (local window cells · object window + profile stations · across samples)).
    """
    c = grid.cell
    low = params.headcut_min_incision_m if lowering_m is None else lowering_m
    kground = max(3, int(round(params.stable_object_window_m / c)) | 1)
    step = params.headcut_profile_step_m
    s = np.arange(-params.headcut_search_radius_m, params.headcut_window_m + _PLATEAU_M + 1e-9, step)
    span = params.headcut_search_radius_m + params.headcut_thalweg_halfwidth_m + 2 * params.headcut_window_m + kground * c
    rows = []
    for hid, x, y in zip(heads["head_id"], heads["x"], heads["y"]):
        row = dict.fromkeys(COLUMNS, np.nan)
        row.update(head_id=hid, x_digitised=x, y_digitised=y)
        ch = locate_channel(z1, grid, float(x), float(y), params)
        if ch is not None:
            hx, hy, tx, ty = ch
            t = np.array([tx, ty])
            ra, rb, ca, cb, _, _ = _window(grid, hx, hy, int(np.ceil(span / c)) + 2)
            found = []
            for z in (z1, z2):
                zw = z[ra:rb, ca:cb].astype(np.float64)
                prof = depth_profile(zw, ground_surface(zw, kground), grid, (ra, ca), hx, hy, t, s, params)
                found.append(locate_head(s, prof, params))
            h1, h2 = found
            row.update(axis_x=tx, axis_y=ty, incision1_m=h1["bottom"] - h1["top"], incision2_m=h2["bottom"] - h2["top"],
                       x1=hx + h1["lip"] * tx, y1=hy + h1["lip"] * ty, x2=hx + h2["lip"] * tx, y2=hy + h2["lip"] * ty,
                       retreat_m=h1["lip"] - h2["lip"], retreat_mid_m=h1["mid"] - h2["mid"])
            lx, ly = (hx + h1["lip"] * tx, hy + h1["lip"] * ty) if np.isfinite(h1["lip"]) else (hx, hy)
            row["retreat_dod_m"] = _dod_reach_local(z1, z2, grid, lx, ly, -t, params, low)
        rows.append(row)
    df = pd.DataFrame(rows, columns=COLUMNS)
    if len(df):
        log.info("headcuts: %d heads, %d located on both DEMs; median retreat %.2f m (lip), %.2f m (half height), %.2f m (DoD reach)",
                 len(df), int(df["retreat_m"].notna().sum()), float(df["retreat_m"].median()),
                 float(df["retreat_mid_m"].median()), float(df["retreat_dod_m"].median()))
    return df


def _dod_reach_local(z1: np.ndarray, z2: np.ndarray, grid: GridSpec, x: float, y: float, up: np.ndarray,
                     params: ChangeParams, lowering_m: float) -> float:
    """:func:`dod_reach` on the DoD of a window around (x, y) only."""
    pad = int(np.ceil(params.headcut_search_radius_m / grid.cell)) + 1
    ra, rb, ca, cb, _, _ = _window(grid, x, y, pad)
    sub = grid.window(ra, ca, rb - ra, cb - ca)
    return dod_reach(z2[ra:rb, ca:cb] - z1[ra:rb, ca:cb], sub, x, y, up, params.headcut_search_radius_m, lowering_m,
                     2 * grid.cell + 0.5)
