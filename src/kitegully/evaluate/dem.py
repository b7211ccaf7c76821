"""DEM validation: checkpoint sampling, error statistics, error rasters and profiles.

Errors are always ``e = z_model − z_reference`` (positive: the model is too high). The
statistics follow the style of Feurer et al. 2018 Table 3 (mean, median, SD, RMSE, NMAD,
5th and 95th percentiles, n) and Table 5 (min, quartiles, median, mean, SD, max).
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np
import pandas as pd

from kitegully import InputError
from kitegully.io.raster import GridSpec

STAT_NAMES = ("mean", "median", "sd", "rmse", "nmad", "p05", "p95", "n")
PROFILE_STAT_NAMES = ("min", "q25", "median", "q75", "max", "mean", "sd", "n")


def sample_bilinear(z: np.ndarray, grid: GridSpec, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Bilinear interpolation of raster ``z`` at map points; NaN outside the grid or where
    any of the four surrounding cell centres is NaN. Points between the outermost cell
    centres and the grid edge take the nearest edge values. O(points)."""
    r, c = grid.rowcol(np.asarray(x, float), np.asarray(y, float))
    H, W = z.shape
    inside = (r >= -0.5) & (c >= -0.5) & (r <= H - 0.5) & (c <= W - 0.5)
    r = np.clip(r, 0, H - 1)
    c = np.clip(c, 0, W - 1)
    r0 = np.clip(np.floor(r).astype(int), 0, max(H - 2, 0))
    c0 = np.clip(np.floor(c).astype(int), 0, max(W - 2, 0))
    r1 = np.minimum(r0 + 1, H - 1)
    c1 = np.minimum(c0 + 1, W - 1)
    a = r - r0
    b = c - c0
    v = ((1 - a) * ((1 - b) * z[r0, c0] + b * z[r0, c1]) + a * ((1 - b) * z[r1, c0] + b * z[r1, c1]))
    return np.where(inside, v, np.nan)


def sample_nearest(z: np.ndarray, grid: GridSpec, x: np.ndarray, y: np.ndarray, fill=0) -> np.ndarray:
    """Value of the cell containing each map point (``fill`` outside the grid, 0 by default)."""
    r, c = grid.rowcol(np.asarray(x, float), np.asarray(y, float))
    r = np.rint(r).astype(int)
    c = np.rint(c).astype(int)
    inside = (r >= 0) & (c >= 0) & (r < z.shape[0]) & (c < z.shape[1])
    out = np.full(r.shape, fill, dtype=z.dtype)
    out[inside] = z[r[inside], c[inside]]
    return out


def error_stats(e: np.ndarray) -> dict[str, float]:
    """Error statistics of finite values of ``e``: mean, median, SD (ddof 1), RMSE, NMAD
    (1.4826 · median |e − median|), 5th and 95th percentiles and n; NaN stats when n = 0."""
    e = np.asarray(e, float)
    e = e[np.isfinite(e)]
    n = e.size
    if n == 0:
        return {k: (0 if k == "n" else float("nan")) for k in STAT_NAMES}
    med = float(np.median(e))
    return {
        "mean": float(e.mean()),
        "median": med,
        "sd": float(e.std(ddof=1)) if n > 1 else float("nan"),
        "rmse": float(np.sqrt(np.mean(e * e))),
        "nmad": float(1.4826 * np.median(np.abs(e - med))),
        "p05": float(np.percentile(e, 5)),
        "p95": float(np.percentile(e, 95)),
        "n": int(n),
    }


def profile_stats(v: np.ndarray) -> dict[str, float]:
    """Table 5 statistics of the finite values of ``v``: min, quartiles, median, max, mean, SD, n."""
    v = np.asarray(v, float)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return {k: (0 if k == "n" else float("nan")) for k in PROFILE_STAT_NAMES}
    q = np.percentile(v, [0, 25, 50, 75, 100])
    return {"min": q[0], "q25": q[1], "median": q[2], "q75": q[3], "max": q[4], "mean": float(v.mean()),
            "sd": float(v.std(ddof=1)) if v.size > 1 else float("nan"), "n": int(v.size)}


def summary_table(e: np.ndarray) -> pd.DataFrame:
    """``statistic, value_m`` table of :func:`error_stats` (n is a count)."""
    s = error_stats(e)
    return pd.DataFrame({"statistic": list(s), "value_m": [s[k] for k in s]})


def read_checkpoints(path: str | Path) -> pd.DataFrame:
    """Checkpoints CSV with columns ``id, x, y, z`` (m, site CRS); InputError names the file."""
    path = Path(path)
    try:
        df = pd.read_csv(path)
    except (OSError, pd.errors.ParserError, pd.errors.EmptyDataError) as exc:
        raise InputError(f"{path}: cannot read checkpoints ({exc})") from None
    missing = [c for c in ("id", "x", "y", "z") if c not in df.columns]
    if missing:
        raise InputError(f"{path}: checkpoint file lacks column(s) {', '.join(missing)} (expected id, x, y, z)")
    vals = df[["x", "y", "z"]].apply(pd.to_numeric, errors="coerce")
    if vals.isna().any().any():
        raise InputError(f"{path}: non-numeric or empty x, y or z in row(s) {list(np.where(vals.isna().any(axis=1))[0][:5] + 2)}")
    if len(df) == 0:
        raise InputError(f"{path}: no checkpoints")
    df[["x", "y", "z"]] = vals
    return df


def checkpoint_errors(dsm: np.ndarray, grid: GridSpec, points: pd.DataFrame) -> pd.DataFrame:
    """One row per checkpoint: ``id, x_m, y_m, z_ref_m, z_model_m, error_m`` (NaN where the
    DSM has no value there)."""
    zm = sample_bilinear(dsm, grid, points["x"].to_numpy(), points["y"].to_numpy())
    return pd.DataFrame({
        "id": points["id"].to_numpy(), "x_m": points["x"].to_numpy(), "y_m": points["y"].to_numpy(),
        "z_ref_m": points["z"].to_numpy(), "z_model_m": zm, "error_m": zm - points["z"].to_numpy(),
    })


def resample_to(z: np.ndarray, grid: GridSpec, target: GridSpec, nearest: bool = False) -> np.ndarray:
    """Values of raster ``z`` at the cell centres of ``target`` (bilinear or nearest)."""
    xs, ys = target.cell_centres()
    X, Y = np.meshgrid(xs, ys)
    if nearest:
        return sample_nearest(z, grid, X, Y)
    return sample_bilinear(z, grid, X, Y)


def error_raster(model: np.ndarray, grid: GridSpec, reference: np.ndarray, ref_grid: GridSpec) -> np.ndarray:
    """``model − reference`` on the model's grid (reference resampled bilinearly when the
    grids differ). Raises InputError when the CRSs differ or the grids do not overlap."""
    if grid.crs != ref_grid.crs:
        raise InputError(f"reference DEM CRS {ref_grid.crs} differs from the model's {grid.crs}")
    ref = reference if ref_grid == grid else resample_to(reference, ref_grid, grid)
    if not np.isfinite(ref).any():
        raise InputError("reference DEM does not overlap the model grid")
    return (model - ref).astype(np.float32)


def stats_by_class(err: np.ndarray, classes: np.ndarray, names: dict[int, str]) -> pd.DataFrame:
    """Error statistics per land-cover class (plus ``all``): columns ``landcover``,
    ``mean_m, median_m, sd_m, rmse_m, nmad_m, p05_m, p95_m, n``, and the area share."""
    rows = [{"landcover": "all", **error_stats(err)}]
    for code in sorted(names):
        m = classes == code
        if m.any():
            rows.append({"landcover": names[code], **error_stats(err[m])})
    df = pd.DataFrame(rows)
    return df.rename(columns={k: f"{k}_m" for k in STAT_NAMES if k != "n"})


def profile_points(vertices: Sequence[Sequence[float]], spacing: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points every ``spacing`` m along a polyline: (distance, x, y)."""
    V = np.asarray(vertices, float)
    if V.ndim != 2 or V.shape[1] != 2 or len(V) < 2:
        raise InputError("profile polyline: give at least two [x, y] vertices")
    seg = np.hypot(*np.diff(V, axis=0).T)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    d = np.arange(0.0, cum[-1] + 1e-9, spacing)
    return d, np.interp(d, cum, V[:, 0]), np.interp(d, cum, V[:, 1])


def profile_comparison(model: np.ndarray, grid: GridSpec, reference: np.ndarray, ref_grid: GridSpec,
                       vertices, spacing: float, classes: np.ndarray | None = None,
                       class_grid: GridSpec | None = None, vegetation_codes: Sequence[int] = ()) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Sample model and reference along a polyline (Feurer et al. 2018 Fig. 10, Table 5).

    Returns the profile (``distance_m, x_m, y_m, z_model_m, z_ref_m, error_m, vegetation``)
    and the statistics table of the errors for the whole profile and without vegetation
    (rows ``whole``, ``no_vegetation``; columns ``min_m … sd_m, n``).
    """
    d, x, y = profile_points(vertices, spacing)
    zm = sample_bilinear(model, grid, x, y)
    zr = sample_bilinear(reference, ref_grid, x, y)
    veg = np.zeros(d.shape, bool)
    if classes is not None and class_grid is not None and len(vegetation_codes):
        veg = np.isin(sample_nearest(classes, class_grid, x, y), list(vegetation_codes))
    prof = pd.DataFrame({"distance_m": d, "x_m": x, "y_m": y, "z_model_m": zm, "z_ref_m": zr, "error_m": zm - zr, "vegetation": veg})
    rows = []
    for name, m in (("whole", np.ones(d.shape, bool)), ("no_vegetation", ~veg)):
        s = profile_stats((zm - zr)[m])
        rows.append({"profile": name, **{(k if k == "n" else f"{k}_m"): s[k] for k in PROFILE_STAT_NAMES}})
    return prof, pd.DataFrame(rows)
