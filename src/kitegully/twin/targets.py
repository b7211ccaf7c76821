"""Ground control targets: placement on open, gentle ground and painting into the texture."""

from __future__ import annotations

import numpy as np
import pandas as pd

from kitegully import InputError
from kitegully.io.raster import GridSpec
from kitegully.seeds import rng_for
from kitegully.twin.landcover import CODE


def sample_nearest(arr: np.ndarray, grid: GridSpec, x: np.ndarray, y: np.ndarray, fill: float = 0) -> np.ndarray:
    """Value of the cell containing each point (``fill`` outside the grid).

    Parameters
    ----------
    arr : ndarray (H, W)
        Raster on ``grid``.
    grid : GridSpec
        The raster's grid.
    x, y : ndarray
        Map coordinates (m).
    fill : scalar
        Value for points outside the grid.

    Returns
    -------
    ndarray
        One value per point, of ``arr``'s dtype.
    """
    r, c = grid.rowcol(x, y)
    ri = np.round(r).astype(np.int64)
    ci = np.round(c).astype(np.int64)
    ok = (ri >= 0) & (ri < grid.height) & (ci >= 0) & (ci < grid.width)
    out = np.full(np.shape(ri), fill, dtype=arr.dtype)
    out[ok] = arr[ri[ok], ci[ok]]
    return out


def sample_bilinear(arr: np.ndarray, grid: GridSpec, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Bilinear interpolation between cell centres (NaN outside the grid).

    Parameters
    ----------
    arr : ndarray (H, W)
        Raster on ``grid``.
    grid : GridSpec
        The raster's grid.
    x, y : ndarray
        Map coordinates (m).

    Returns
    -------
    ndarray float64
        One value per point; NaN beyond the outermost cell centres.
    """
    r, c = grid.rowcol(np.asarray(x, float), np.asarray(y, float))
    ok = (r >= 0) & (r <= grid.height - 1) & (c >= 0) & (c <= grid.width - 1)
    r = np.clip(r, 0, grid.height - 1.000001)
    c = np.clip(c, 0, grid.width - 1.000001)
    r0 = r.astype(np.int64)
    c0 = c.astype(np.int64)
    fr, fc = r - r0, c - c0
    v = (arr[r0, c0] * (1 - fr) * (1 - fc) + arr[r0, c0 + 1] * (1 - fr) * fc
         + arr[r0 + 1, c0] * fr * (1 - fc) + arr[r0 + 1, c0 + 1] * fr * fc)
    return np.where(ok, v, np.nan)


def stencil(radius: float, step: float) -> tuple[np.ndarray, np.ndarray]:
    """Offsets of a square lattice of points within ``radius`` (m), spacing ``step``."""
    n = int(np.ceil(radius / step))
    o = np.arange(-n, n + 1) * step
    dx, dy = np.meshgrid(o, o)
    keep = dx**2 + dy**2 <= radius**2 + 1e-9
    return dx[keep], dy[keep]


def eligible(lc: np.ndarray, grid: GridSpec, x: np.ndarray, y: np.ndarray, classes: list[str],
             radius: float) -> np.ndarray:
    """True where every cell within ``radius`` of a point has one of ``classes``.

    Parameters
    ----------
    lc : ndarray (H, W)
        Land-cover codes on ``grid``.
    grid : GridSpec
        The grid of ``lc``.
    x, y : ndarray
        Map coordinates of the points (m).
    classes : list of str
        Land-cover names allowed.
    radius : float
        Radius checked around each point (m), sampled on a lattice of one cell.

    Returns
    -------
    ndarray (len(x),) bool
    """
    codes = np.array([CODE[c] for c in classes], dtype=np.uint8)
    dx, dy = stencil(radius, grid.cell)
    ok = np.ones(len(x), dtype=bool)
    for ox, oy in zip(dx, dy):
        ok &= np.isin(sample_nearest(lc, grid, x + ox, y + oy), codes)
    return ok


def select_gcps(tcfg: dict, lc: np.ndarray, dsm: np.ndarray, grid: GridSpec, seed: int) -> pd.DataFrame:
    """Spread ``count`` targets over open, gentle ground by farthest-point sampling.

    Candidates are drawn uniformly (``edge_margin_m`` from the border); a candidate is kept
    when all cells under the target plus ``clearance_m`` are of ``classes`` and the local
    slope is below ``max_slope_deg``. Returns ``gcp_id, x, y, z, size_m`` (z on the DSM).

    Parameters
    ----------
    tcfg : mapping
        ``twin.targets``; reads ``count``, ``candidates``, ``edge_margin_m`` (m), ``size_m`` (m),
        ``classes``, ``clearance_m`` (m) and ``max_slope_deg`` (degrees).
    lc : ndarray (H, W)
        Land-cover codes on ``grid``.
    dsm : ndarray (H, W)
        Surface elevation (m) on ``grid``.
    grid : GridSpec
        The DEM grid.
    seed : int
        Master seed.

    Returns
    -------
    DataFrame
        One row per target, ``gcp_id`` ``GCP01``, ``GCP02``, ...; the first is the candidate nearest
        the grid's top-left corner.
    """
    rng = rng_for(seed, "twin", "gcp_targets")
    xmin, ymin, xmax, ymax = grid.bounds
    m = tcfg["edge_margin_m"]
    n_cand = tcfg["candidates"]
    x = rng.uniform(xmin + m, xmax - m, n_cand)
    y = rng.uniform(ymin + m, ymax - m, n_cand)
    size = tcfg["size_m"]
    ok = eligible(lc, grid, x, y, tcfg["classes"], size / np.sqrt(2) + tcfg["clearance_m"])
    d = 1.0
    zx = (sample_bilinear(dsm, grid, x + d, y) - sample_bilinear(dsm, grid, x - d, y)) / (2 * d)
    zy = (sample_bilinear(dsm, grid, x, y + d) - sample_bilinear(dsm, grid, x, y - d)) / (2 * d)
    slope = np.degrees(np.arctan(np.hypot(zx, zy)))
    ok &= slope < tcfg["max_slope_deg"]
    x, y = x[ok], y[ok]
    if len(x) < tcfg["count"]:
        raise InputError(f"twin.targets: only {len(x)} eligible places for {tcfg['count']} GCP targets on this site; lower count or relax classes, clearance_m or max_slope_deg")
    chosen = [int(np.argmin((x - xmin) ** 2 + (y - ymax) ** 2))]
    dmin = np.hypot(x - x[chosen[0]], y - y[chosen[0]])
    for _ in range(tcfg["count"] - 1):
        i = int(np.argmax(dmin))
        chosen.append(i)
        dmin = np.minimum(dmin, np.hypot(x - x[i], y - y[i]))
    cx, cy = x[chosen], y[chosen]
    z = sample_bilinear(dsm, grid, cx, cy)
    ids = [f"GCP{i + 1:02d}" for i in range(len(chosen))]
    return pd.DataFrame({"gcp_id": ids, "x": cx, "y": cy, "z": z, "size_m": size})


def paint_targets(refl: np.ndarray, tx: np.ndarray, ty: np.ndarray, targets: pd.DataFrame, tcfg: dict) -> None:
    """Paint square targets into a reflectance tile ``refl`` (bands, rows, cols) in place.

    ``checker``: a white square whose inner part is a 2×2 black/white checker (the centre
    is the checker corner); ``cross``: a white square with a black cross through the centre.

    Parameters
    ----------
    refl : ndarray (bands, rows, cols) float
        Reflectance tile; changed in place.
    tx : ndarray (cols,)
        Map x of the texel centres (m).
    ty : ndarray (rows,)
        Map y of the texel centres (m).
    targets : DataFrame
        Targets with ``x``, ``y`` and ``size_m`` (m).
    tcfg : mapping
        ``twin.targets``; reads ``pattern``, ``white_reflectance`` and ``black_reflectance`` (per band),
        ``border_fraction`` and ``cross_bar_fraction``.
    """
    white = np.asarray(tcfg["white_reflectance"], dtype=refl.dtype)[:, None, None]
    black = np.asarray(tcfg["black_reflectance"], dtype=refl.dtype)[:, None, None]
    xmin, xmax = tx.min(), tx.max()
    ymin, ymax = ty.min(), ty.max()
    for t in targets.itertuples():
        h = 0.5 * t.size_m
        if t.x + h < xmin or t.x - h > xmax or t.y + h < ymin or t.y - h > ymax:
            continue
        cols = np.nonzero(np.abs(tx - t.x) <= h)[0]
        rows = np.nonzero(np.abs(ty - t.y) <= h)[0]
        if not len(cols) or not len(rows):
            continue
        dx = tx[cols][None, :] - t.x
        dy = ty[rows][:, None] - t.y
        inner = np.maximum(np.abs(dx), np.abs(dy)) <= h * (1.0 - tcfg["border_fraction"])
        if tcfg["pattern"] == "checker":
            dark = inner & ((dx > 0) == (dy > 0))
        else:
            bar = tcfg["cross_bar_fraction"] * t.size_m * 0.5
            dark = inner & ((np.abs(dx) <= bar) | (np.abs(dy) <= bar))
        sub = refl[:, rows[0]:rows[-1] + 1, cols[0]:cols[-1] + 1]
        sub[:] = np.where(dark[None], black, white)
