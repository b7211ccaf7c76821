"""Co-registration of epoch 2 onto epoch 1 on stable ground: Nuth & Kääb (2011) shift + plane.

Nuth & Kääb: a horizontal shift Δ of DEM₂ against DEM₁ shows on stable ground as
``dh / tan α = −|Δ| cos(b − ψ) + c`` (α slope, ψ aspect, b the shift direction). We solve
the same relation in its equivalent linear form ``dh = −∂z/∂x·Δx − ∂z/∂y·Δy + p₀ + p₁x + p₂y``
(the cosine fit multiplied by tan α, i.e. weighted by tan²α, which is the least-squares
solution when dh noise does not depend on slope), jointly with the plane (vertical bias and
tilt). The linearisation holds for small shifts, so it is iterated: resample DEM₂ at the
accumulated shift, refit, until the shift increment is below a tolerance. Each fit is
trimmed at ``outlier_nmad`` NMAD around the median residual (vegetation, missed change).
"""

from __future__ import annotations

import logging
from dataclasses import asdict, dataclass, field
from typing import Callable

import numpy as np
import pandas as pd
from scipy import ndimage

from kitegully.change.dod import resample
from kitegully.change.params import ChangeParams
from kitegully.evaluate.dem import nmad
from kitegully.io.raster import GridSpec, Raster

log = logging.getLogger(__name__)


def residual_stats(dh: np.ndarray) -> dict[str, float]:
    """Median, NMAD, mean, SD, RMSE and n of the finite values of ``dh`` (m)."""
    d = dh[np.isfinite(dh)].astype(np.float64)
    if d.size == 0:
        return dict(median_m=np.nan, nmad_m=np.nan, mean_m=np.nan, sd_m=np.nan, rmse_m=np.nan, n=0)
    return dict(median_m=float(np.median(d)), nmad_m=nmad(d), mean_m=float(d.mean()), sd_m=float(d.std()),
                rmse_m=float(np.sqrt(np.mean(d**2))), n=int(d.size))


@dataclass
class Coregistration:
    """Applied correction and stable-ground residuals (DEM₂ corrected = DEM₂(x + Δ) − plane).

    ``offset_sd_m`` is the SD of the vertical offset estimate (set by the stage from the
    stable-ground variogram; NaN when not estimated).
    """

    dx_m: float = 0.0
    dy_m: float = 0.0
    dz_m: float = 0.0
    tilt_x: float = 0.0
    tilt_y: float = 0.0
    x_centre: float = 0.0
    y_centre: float = 0.0
    iterations: int = 0
    converged: bool = False
    offset_sd_m: float = float("nan")
    before: dict = field(default_factory=dict)
    after: dict = field(default_factory=dict)

    def plane(self, grid: GridSpec) -> np.ndarray:
        """The removed plane on ``grid`` (m)."""
        xs, ys = grid.cell_centres()
        return (self.dz_m + self.tilt_x * (xs[None, :] - self.x_centre)
                + self.tilt_y * (ys[:, None] - self.y_centre)).astype(np.float32)

    def table(self) -> pd.DataFrame:
        """One row per quantity: applied shift/tilt and residuals before/after."""
        rows = [("dx", self.dx_m, "m"), ("dy", self.dy_m, "m"), ("dz_at_centre", self.dz_m, "m"),
                ("tilt_x", self.tilt_x * 1000, "m/km"), ("tilt_y", self.tilt_y * 1000, "m/km"),
                ("offset_sd", self.offset_sd_m, "m"),
                ("iterations", self.iterations, "-"), ("converged", int(self.converged), "-")]
        for when, st in (("before", self.before), ("after", self.after)):
            rows += [(f"stable_{k.removesuffix('_m')}_{when}", v, "m" if k.endswith("_m") else "cells") for k, v in st.items()]
        return pd.DataFrame(rows, columns=["quantity", "value", "unit"])

    def as_dict(self) -> dict:
        """Every field as a plain dict (:func:`dataclasses.asdict`)."""
        return asdict(self)


def height_above_ground(z: np.ndarray, cell: float, window_m: float, fill: float | None = None) -> np.ndarray:
    """Height (m) of each cell above the grey opening (a ``window_m`` square) of the box-smoothed surface.

    Objects narrower than the window (shrubs, trees, buildings) stand above it, the ground
    does not. Nodata cells take ``fill`` for the filters (default the highest elevation of
    ``z``; a tile of a larger grid passes the whole grid's). O(cells · window).

    Parameters
    ----------
    z : ndarray (H, W)
        Surface elevations (m); NaN is nodata.
    cell : float
        Cell size (m).
    window_m : float
        Side of the opening's square window (m), rounded to an odd number of cells (at least 3).
    fill : float or None
        Elevation (m) given to nodata cells; None takes the highest elevation of ``z``.

    Returns
    -------
    ndarray (H, W)
        Height above the ground (m).
    """
    k = max(3, int(round(window_m / cell)) | 1)
    zf = np.where(np.isfinite(z), z, np.nanmax(z) if fill is None else fill)
    # a box mean over a third of the window first: the opening is a lower envelope, and of a
    # noisy surface it sits ~3 σ low (white noise of 0.05 m alone then "stands" 0.15 m high)
    zf = ndimage.uniform_filter(zf, max(3, (k // 3) | 1), mode="nearest")
    return zf - ndimage.grey_opening(zf, size=(k, k))


def above_ground(z: np.ndarray, cell: float, window_m: float, height_m: float, fill: float | None = None) -> np.ndarray:
    """Cells standing more than ``height_m`` above the ground (:func:`height_above_ground`), dilated by half a window.

    Shrubs, trees and buildings: not stable ground (vegetation grows and moves, dense
    matching smooths it); the dilation catches their edges. O(cells · window).

    Parameters
    ----------
    z : ndarray (H, W)
        Surface elevations (m); NaN is nodata.
    cell : float
        Cell size (m).
    window_m : float
        Side of the opening's square window (m).
    height_m : float
        Height above the ground (m) above which a cell stands out.
    fill : float or None
        Elevation (m) given to nodata cells; None takes the highest elevation of ``z``.

    Returns
    -------
    ndarray (H, W) bool
        Cells above the ground, dilated.
    """
    k = max(3, int(round(window_m / cell)) | 1)
    h = height_above_ground(z, cell, window_m, fill)
    obj = np.isfinite(h) & (h > height_m)
    return ndimage.binary_dilation(obj, structure=np.ones((k // 2 | 1, k // 2 | 1), bool))


def above_ground_halo(cell: float, window_m: float) -> int:
    """Cells beyond a window that :func:`above_ground` reads for the window's cells (box mean, opening, dilation)."""
    k = max(3, int(round(window_m / cell)) | 1)
    return max(3, (k // 3) | 1) // 2 + 2 * (k // 2) + (k // 2 | 1) // 2


def _sample(idx: np.ndarray, n: int) -> np.ndarray:
    if idx.size <= n:
        return idx
    return idx[np.linspace(0, idx.size - 1, n).astype(np.int64)]


def coregister(z1: np.ndarray, dem2: Raster, grid: GridSpec, stable: np.ndarray,
               params: ChangeParams) -> tuple[np.ndarray, Coregistration]:
    """Shift and tilt DEM₂ onto DEM₁ using stable ground.

    Parameters
    ----------
    z1 : ndarray (H, W)
        Epoch-1 DEM on ``grid`` (m), the reference.
    dem2 : Raster
        Epoch-2 DEM on its own grid (resampled here at each shift, never twice).
    grid : GridSpec
        The common grid.
    stable : ndarray of bool (H, W)
        Stable ground (no change expected).
    params : ChangeParams

    Returns
    -------
    z2 : ndarray (H, W) float32
        Co-registered epoch-2 DEM on ``grid``.
    info : Coregistration

    Notes
    -----
    O(iterations × cells): one bilinear resampling of DEM₂ and one least-squares fit on at
    most ``coreg_max_samples`` cells per iteration.
    """
    xs, ys = grid.cell_centres()
    xc, yc = float(xs.mean()), float(ys.mean())
    gy, gx = np.gradient(z1.astype(np.float64), grid.cell)
    gy = -gy  # rows go south: ∂z/∂y = −∂z/∂row
    tan_a = np.hypot(gx, gy)
    max_tan = np.tan(np.radians(params.coreg_max_slope_deg))
    z2 = resample(dem2, grid)
    info = Coregistration(x_centre=xc, y_centre=yc)
    info.before = residual_stats(np.where(stable, z2 - z1, np.nan))
    if not params.coreg_enabled:
        info.after = info.before
        return z2, info
    base = stable & np.isfinite(z1) & np.isfinite(tan_a) & (tan_a <= max_tan)
    idx = _sample(np.flatnonzero(base), params.coreg_max_samples)
    if idx.size < 100:
        log.warning("only %d stable cells: co-registration skipped", idx.size)
        info.after = info.before
        return z2, info
    rr, cc = np.unravel_index(idx, z1.shape)
    fit_shift_plane(info, z1.ravel()[idx], gx.ravel()[idx], gy.ravel()[idx], tan_a.ravel()[idx], xs[cc] - xc, ys[rr] - yc,
                    lambda dx, dy: resample(dem2, grid, dx, dy).ravel()[idx], params)
    z2 = resample(dem2, grid, info.dx_m, info.dy_m) - info.plane(grid)
    info.after = residual_stats(np.where(stable, z2 - z1, np.nan))
    log.info("stable-ground dh NMAD %.3f -> %.3f m, median %.3f -> %.3f m", info.before["nmad_m"],
             info.after["nmad_m"], info.before["median_m"], info.after["median_m"])
    return z2.astype(np.float32), info


def fit_shift_plane(info: Coregistration, z1s: np.ndarray, gxs: np.ndarray, gys: np.ndarray, tans: np.ndarray,
                    px: np.ndarray, py: np.ndarray, z2_at: Callable[[float, float], np.ndarray],
                    params: ChangeParams) -> Coregistration:
    """The iterated Nuth & Kääb shift + plane fit on sampled stable cells; updates and returns ``info``.

    ``z1s`` (float32), ``gxs, gys, tans`` (slope terms, float64) and ``px, py`` (offsets from
    the grid centre, m) are the sampled cells' values; ``z2_at(dx, dy)`` gives DEM₂ resampled
    at those cells shifted by (dx, dy) m (float32). O(iterations × samples).

    Parameters
    ----------
    info : Coregistration
        Start of the fit; its shift, offset and tilt accumulate here.
    z1s : ndarray
        Epoch-1 elevations of the sampled cells (m).
    gxs, gys : ndarray
        Slopes ∂z/∂x and ∂z/∂y of epoch 1 at the sampled cells (m/m).
    tans : ndarray
        Tangent of the slope at the sampled cells; below ``coreg_min_slope_deg`` a cell gets no shift terms.
    px, py : ndarray
        East and north offsets of the sampled cells from the grid centre (m).
    z2_at : callable
        ``z2_at(dx, dy)``: epoch-2 elevations (m) at the sampled cells shifted by (dx, dy) m.
    params : ChangeParams
        Reads the ``coreg_*`` settings (iterations, tolerance, outlier NMAD, tilt, minimum slope).

    Returns
    -------
    Coregistration
        ``info``, updated in place.
    """

    flat = tans < np.tan(np.radians(params.coreg_min_slope_deg))
    for it in range(1, params.coreg_max_iterations + 1):
        info.iterations = it
        dh = z2_at(info.dx_m, info.dy_m) - z1s - (info.dz_m + info.tilt_x * px + info.tilt_y * py)
        ok = np.isfinite(dh)
        med, s = np.median(dh[ok]), nmad(dh[ok])
        ok &= np.abs(dh - med) <= params.coreg_outlier_nmad * max(s, 1e-6)
        cols = [np.where(flat, 0.0, -gxs), np.where(flat, 0.0, -gys), np.ones_like(px)]
        if params.coreg_tilt:
            cols += [px, py]
        A = np.stack(cols, axis=1)[ok]
        sol, *_ = np.linalg.lstsq(A, dh[ok], rcond=None)
        ddx, ddy, ddz = float(sol[0]), float(sol[1]), float(sol[2])
        info.dx_m += ddx
        info.dy_m += ddy
        info.dz_m += ddz
        if params.coreg_tilt:
            info.tilt_x += float(sol[3])
            info.tilt_y += float(sol[4])
        log.info("co-registration iteration %d: shift (%.3f, %.3f) m, dz %.3f m, tilt (%.2e, %.2e); increment %.4f m",
                 it, info.dx_m, info.dy_m, info.dz_m, info.tilt_x, info.tilt_y, np.hypot(ddx, ddy))
        if np.hypot(ddx, ddy) < params.coreg_tolerance_m:
            info.converged = True
            break
    return info
