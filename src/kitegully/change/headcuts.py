"""Headcut retreat per digitised head, measured on the two DEMs.

For each head digitised at epoch 1, in a disc of ``search_radius_m`` around it and on each
DEM separately: incision depth = (Gaussian-smoothed surface, σ = ``incision_sigma_m``) −
DEM; channel cells are those incised deeper than ``min_incision_m``; the channel piece
(8-connected) nearest to the digitised point is this gully, and its head is its highest
cell (a gully runs downhill from its head). A first estimate is the horizontal distance between the
epoch-1 and epoch-2 heads (and its component along the epoch-1 upslope direction; a head
that moves downhill is a measurement artefact). The stated estimate, ``retreat_m``, reads
the retreat from the DoD itself: the piece of significant lowering
(DoD < −``lowering_m``) that touches the epoch-1 head (within ``touch_m``), and how far it
reaches upslope of that head along the epoch-1 upslope direction (0 if none). It does not
depend on finding the epoch-2 head on a noisy DEM, only the epoch-1 one.
"""

from __future__ import annotations

import logging

import numpy as np
import pandas as pd
from scipy import ndimage

from kitegully.change.params import ChangeParams
from kitegully.io.raster import GridSpec

log = logging.getLogger(__name__)


def _smooth_nan(z: np.ndarray, sigma_cells: float) -> np.ndarray:
    ok = np.isfinite(z)
    num = ndimage.gaussian_filter(np.where(ok, z, 0.0), sigma_cells, mode="nearest")
    den = ndimage.gaussian_filter(ok.astype(np.float64), sigma_cells, mode="nearest")
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0.05, num / den, np.nan)


def find_head(z: np.ndarray, grid: GridSpec, x: float, y: float, params: ChangeParams) -> tuple[float, float, float]:
    """(x, y, incision depth) of the channel head nearest (x, y) on DEM ``z``; NaNs if none.

    Works on a window of radius + 4σ around the point: O(window cells).
    """
    c = grid.cell
    rad = params.headcut_search_radius_m / c
    sig = params.headcut_incision_sigma_m / c
    pad = int(np.ceil(rad + 4 * sig))
    r0f, c0f = grid.rowcol(np.array([x]), np.array([y]))
    r0, c0 = int(round(float(r0f[0]))), int(round(float(c0f[0])))
    ra, rb = max(r0 - pad, 0), min(r0 + pad + 1, grid.height)
    ca, cb = max(c0 - pad, 0), min(c0 + pad + 1, grid.width)
    if ra >= rb or ca >= cb:
        return np.nan, np.nan, np.nan
    win = z[ra:rb, ca:cb].astype(np.float64)
    depth = _smooth_nan(win, sig) - win
    rr, cc = np.mgrid[ra:rb, ca:cb]
    disc = np.hypot(rr - r0f[0], cc - c0f[0]) <= rad
    chan = disc & (depth > params.headcut_min_incision_m)
    if not chan.any():
        return np.nan, np.nan, np.nan
    lab, _ = ndimage.label(chan, structure=np.ones((3, 3)))
    d2 = np.where(chan, np.hypot(rr - r0f[0], cc - c0f[0]), np.inf)
    near = lab.ravel()[int(np.argmin(d2))]
    piece = lab == near
    k = int(np.nanargmax(np.where(piece, win, -np.inf)))
    hr, hc = np.unravel_index(k, win.shape)
    xs, ys = grid.xy(ra + hr, ca + hc)
    return float(xs), float(ys), float(depth[hr, hc])


def dod_reach(dod: np.ndarray, grid: GridSpec, x1: float, y1: float, up: np.ndarray, radius_m: float,
              lowering_m: float, touch_m: float) -> float:
    """Upslope reach (m) of the significant-lowering piece touching (x1, y1); 0 when none touches."""
    c = grid.cell
    pad = int(np.ceil(radius_m / c))
    r0f, c0f = grid.rowcol(np.array([x1]), np.array([y1]))
    r0, c0 = int(round(float(r0f[0]))), int(round(float(c0f[0])))
    ra, rb = max(r0 - pad, 0), min(r0 + pad + 1, grid.height)
    ca, cb = max(c0 - pad, 0), min(c0 + pad + 1, grid.width)
    win = dod[ra:rb, ca:cb]
    rr, cc = np.mgrid[ra:rb, ca:cb]
    dist = np.hypot(rr - r0f[0], cc - c0f[0]) * c
    low = (dist <= radius_m) & (win < -lowering_m)
    if not low.any():
        return 0.0
    lab, _ = ndimage.label(low, structure=np.ones((3, 3)))
    touching = np.unique(lab[low & (dist <= touch_m)])
    if touching.size == 0:
        return 0.0
    piece = np.isin(lab, touching)
    px = (cc[piece] - c0f[0]) * c
    py = -(rr[piece] - r0f[0]) * c
    return float(max(0.0, np.max(px * up[0] + py * up[1])))


def measure_headcut_retreat(z1: np.ndarray, z2: np.ndarray, grid: GridSpec, heads: pd.DataFrame,
                            params: ChangeParams, lowering_m: float | None = None) -> pd.DataFrame:
    """Head position on each DEM and the retreat between them, per digitised head.

    Parameters
    ----------
    z1, z2 : ndarray (H, W)
        Epoch-1 and co-registered epoch-2 DEMs on ``grid``.
    heads : DataFrame
        ``head_id, x, y`` of the heads digitised at epoch 1.
    lowering_m : float, optional
        Significant lowering for the DoD estimate (m); default ``min_incision_m``.

    Returns
    -------
    DataFrame
        ``head_id, x_digitised, y_digitised, x1, y1, x2, y2``, ``retreat_m`` (the stated
        estimate: DoD reach upslope of the epoch-1 head), ``retreat_heads_m`` (head to head)
        and ``retreat_heads_upslope_m`` (its upslope component).
    """
    z1s = None
    rows = []
    dod = z2 - z1
    low = params.headcut_min_incision_m if lowering_m is None else lowering_m
    for hid, x, y in zip(heads["head_id"], heads["x"], heads["y"]):
        x1, y1, d1 = find_head(z1, grid, x, y, params)
        x2, y2, d2 = find_head(z2, grid, x1 if np.isfinite(x1) else x, y1 if np.isfinite(y1) else y, params)
        dist = float(np.hypot(x2 - x1, y2 - y1))
        up = reach = np.nan
        if np.isfinite(x1):
            # upslope direction at the epoch-1 head from the smoothed epoch-1 surface
            if z1s is None:
                z1s = ndimage.gaussian_filter(np.nan_to_num(z1, nan=float(np.nanmean(z1))), params.headcut_incision_sigma_m / grid.cell)
                gy, gx = np.gradient(z1s, grid.cell)
            r, c = (int(round(float(v[0]))) for v in grid.rowcol(np.array([x1]), np.array([y1])))
            g = np.array([gx[r, c], -gy[r, c]])
            n = np.hypot(*g)
            u = g / n if n > 0 else np.array([np.nan, np.nan])
            if np.isfinite(dist):
                up = float(np.dot([x2 - x1, y2 - y1], u))
            if n > 0:
                reach = dod_reach(dod, grid, x1, y1, u, params.headcut_search_radius_m, low, 2 * grid.cell + 0.5)
        rows.append(dict(head_id=hid, x_digitised=x, y_digitised=y, x1=x1, y1=y1, incision1_m=d1, x2=x2, y2=y2,
                         incision2_m=d2, retreat_m=reach, retreat_heads_m=dist, retreat_heads_upslope_m=up))
    df = pd.DataFrame(rows)
    log.info("headcuts: %d heads, %d found on DEM 1, median retreat %.2f m (DoD reach), %.2f m (head to head)", len(df),
             int(df["x1"].notna().sum()), float(df["retreat_m"].median()) if len(df) else np.nan,
             float(df["retreat_heads_m"].median()) if len(df) else np.nan)
    return df
