"""DEM validation: checkpoint sampling, error statistics, error rasters and profiles.

Errors are always ``e = z_model − z_reference`` (positive: the model is too high). The
statistics follow the style of Feurer et al. 2018 Table 3 (mean, median, SD, RMSE, NMAD,
5th and 95th percentiles, n) and Table 5 (min, quartiles, median, mean, SD, max).

The validate stage's entry points are :func:`validate_checkpoints` (every site) and
:func:`validate_against_truth` (twin sites, evaluation only), with their parameters
:class:`CheckpointParams` and :class:`TruthParams`, each built from the keys of the
``validate`` config section it uses.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
import pandas as pd

from kitegully import InputError
from kitegully.config import checked_number, config_section
from kitegully.io.raster import GridSpec

STAT_NAMES = ("mean", "median", "sd", "rmse", "nmad", "p05", "p95", "n")
PROFILE_STAT_NAMES = ("min", "q25", "median", "q75", "max", "mean", "sd", "n")

#: Keys of the ``validate`` config section (each entry point's parameters take their own).
VALIDATE_KEYS = ("bare_classes", "vegetation_classes", "histogram_bins", "error_limit_m", "figure_max_px", "profile")


def _common_checks(cfg: Mapping[str, Any]) -> None:
    if "error_limit_m" in cfg:
        checked_number(cfg, "error_limit_m", "validate")
    if "figure_max_px" in cfg:
        checked_number(cfg, "figure_max_px", "validate", 100, strict=False)


@dataclass(frozen=True)
class CheckpointParams:
    """Parameters of :func:`validate_checkpoints` (keys of the ``validate`` section).

    Attributes
    ----------
    bare_classes : tuple of str
        Twin land-cover classes counted as bare ground for the checkpoint target ([I]
        where the DSM is the ground: bare, ploughed, track, gully).
    histogram_bins : int
        Bins of the checkpoint error histogram (at least 5).
    error_limit_m : float
        Colour scale limit of the error map (± m).
    """

    bare_classes: tuple[str, ...]
    histogram_bins: int
    error_limit_m: float

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any]) -> "CheckpointParams":
        """Build from the ``validate`` section or the sub-section of its keys; raises InputError naming a bad key."""
        config_section(cfg, "validate", cls.__dataclass_fields__, optional=VALIDATE_KEYS)
        _common_checks(cfg)
        if cfg["histogram_bins"] < 5:
            raise InputError(f"validate.histogram_bins: must be at least 5, got {cfg['histogram_bins']!r}")
        return cls(tuple(cfg["bare_classes"]), cfg["histogram_bins"], cfg["error_limit_m"])


@dataclass(frozen=True)
class ProfileParams:
    """The profile across a gully (``validate.profile``; Feurer et al. 2018 Fig. 10, Table 5).

    Attributes
    ----------
    polyline : list of [x, y] or None
        Profile vertices in the site CRS (m); None = across the longest true gully
        centreline (twins).
    auto_length_m : float
        Length of the automatic profile (m).
    spacing_m : float
        Sample spacing along the profile (m; [I] the DSM cell).
    reference : str
        Truth surface the profile is compared with: ``dtm`` (the field-surveyed ground, as
        in the paper [P]) or ``dsm``.
    """

    polyline: list | None
    auto_length_m: float
    spacing_m: float
    reference: str

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any]) -> "ProfileParams":
        """Build from ``validate.profile``; raises InputError naming a bad key."""
        config_section(cfg, "validate.profile", cls.__dataclass_fields__)
        if cfg["reference"] not in ("dtm", "dsm"):
            raise InputError(f"validate.profile.reference: must be dtm or dsm, got {cfg['reference']!r}")
        for key in ("auto_length_m", "spacing_m"):
            checked_number(cfg, key, "validate.profile")
        line = cfg["polyline"]
        if line is not None and (len(line) < 2 or any(len(v) != 2 for v in line)):
            raise InputError("validate.profile.polyline: must be null or at least two [x, y] vertices")
        return cls(line, cfg["auto_length_m"], cfg["spacing_m"], cfg["reference"])


@dataclass(frozen=True)
class TruthParams:
    """Parameters of :func:`validate_against_truth` (keys of the ``validate`` section).

    Attributes
    ----------
    vegetation_classes : tuple of str
        Land-cover classes left out of the "without vegetation" profile statistics (Table 5).
    error_limit_m : float
        Colour scale limit of the error map (± m).
    figure_max_px : int
        The error raster map is decimated to at most this many pixels per side.
    profile : ProfileParams
        The profile across a gully.
    """

    vegetation_classes: tuple[str, ...]
    error_limit_m: float
    figure_max_px: int
    profile: ProfileParams

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any]) -> "TruthParams":
        """Build from the ``validate`` section or the sub-section of its keys; raises InputError naming a bad key."""
        config_section(cfg, "validate", cls.__dataclass_fields__, optional=VALIDATE_KEYS)
        _common_checks(cfg)
        return cls(tuple(cfg["vegetation_classes"]), cfg["error_limit_m"], cfg["figure_max_px"],
                   ProfileParams.from_config(cfg["profile"]))


def sample_bilinear(z: np.ndarray, grid: GridSpec, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Bilinear interpolation of raster ``z`` at map points; NaN outside the grid or where
    any of the four surrounding cell centres is NaN. Points between the outermost cell
    centres and the grid edge take the nearest edge values. O(points).

    Parameters
    ----------
    z : ndarray (H, W)
        Raster values.
    grid : GridSpec
        Grid of ``z``.
    x, y : ndarray
        Map coordinates of the points (m, CRS of ``grid``).

    Returns
    -------
    ndarray float64
        Interpolated value at each point, in the shape of ``x``.
    """
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


def sample_nearest(z: np.ndarray, grid: GridSpec, x: np.ndarray, y: np.ndarray, fill: float = 0) -> np.ndarray:
    """Value of the cell containing each map point (``fill`` outside the grid, 0 by default).

    Parameters
    ----------
    z : ndarray (H, W)
        Raster values.
    grid : GridSpec
        Grid of ``z``.
    x, y : ndarray
        Map coordinates of the points (m, CRS of ``grid``).
    fill : scalar
        Value of points outside the grid.

    Returns
    -------
    ndarray
        Cell value at each point, in the shape of ``x`` and the dtype of ``z``.
    """
    r, c = grid.rowcol(np.asarray(x, float), np.asarray(y, float))
    r = np.rint(r).astype(int)
    c = np.rint(c).astype(int)
    inside = (r >= 0) & (c >= 0) & (r < z.shape[0]) & (c < z.shape[1])
    out = np.full(r.shape, fill, dtype=z.dtype)
    out[inside] = z[r[inside], c[inside]]
    return out


def nmad(x: np.ndarray) -> float:
    """Normalised median absolute deviation of the finite values, 1.4826 · median(|x − median x|); NaN if none."""
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    if x.size == 0:
        return float("nan")
    return float(1.4826 * np.median(np.abs(x - np.median(x))))


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
        "nmad": nmad(e),
        "p05": float(np.percentile(e, 5)),
        "p95": float(np.percentile(e, 95)),
        "n": int(n),
    }


def sd_without_blunders(e: np.ndarray, outlier_nmad: float | None = 4.0) -> tuple[float, np.ndarray]:
    """SD (ddof 1) of the errors ``e`` with the blunders left out, and which were kept.

    A blunder is an error farther than ``outlier_nmad`` NMADs from the median: a checkpoint on
    a gross matching error of metres, which a plain SD would average in (robust DEM accuracy
    after Höhle & Höhle 2009). [I] 4: a normal error passes with probability 0.99994, so on a
    blunder-free set the SD is the plain one. Fewer than 3 kept, a zero NMAD or
    ``outlier_nmad`` None: the SD of all. O(n log n) for n errors.

    Parameters
    ----------
    e : ndarray
        Errors (m), e.g. DEM minus checkpoint; non-finite values are ignored.
    outlier_nmad : float or None
        Blunder distance from the median in NMADs.

    Returns
    -------
    sd : float
        SD of the kept errors (NaN with fewer than 2 finite errors).
    kept : ndarray bool
        Per finite error of ``e`` (in order), True where it was kept.
    """
    e = np.asarray(e, float)
    e = e[np.isfinite(e)]
    kept = np.ones(e.size, dtype=bool)
    if e.size < 2:
        return float("nan"), kept
    spread = nmad(e)
    if outlier_nmad is not None and spread > 0:
        kept = np.abs(e - np.median(e)) <= outlier_nmad * spread
        if kept.sum() < 3:
            kept[:] = True
    return float(e[kept].std(ddof=1)), kept


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
    DSM has no value there).

    Parameters
    ----------
    dsm : ndarray (H, W)
        The DSM (m), NaN nodata.
    grid : GridSpec
        Grid of ``dsm``.
    points : DataFrame
        Checkpoints with columns ``id, x, y, z`` (m, site CRS; :func:`read_checkpoints`).

    Returns
    -------
    DataFrame
        One row per checkpoint; ``error_m`` is the bilinear DSM value minus ``z`` (m).
    """
    zm = sample_bilinear(dsm, grid, points["x"].to_numpy(), points["y"].to_numpy())
    return pd.DataFrame({
        "id": points["id"].to_numpy(), "x_m": points["x"].to_numpy(), "y_m": points["y"].to_numpy(),
        "z_ref_m": points["z"].to_numpy(), "z_model_m": zm, "error_m": zm - points["z"].to_numpy(),
    })


def resample_to(z: np.ndarray, grid: GridSpec, target: GridSpec, nearest: bool = False) -> np.ndarray:
    """Values of raster ``z`` at the cell centres of ``target`` (bilinear or nearest).

    Parameters
    ----------
    z : ndarray (H, W)
        Raster values.
    grid : GridSpec
        Grid of ``z``.
    target : GridSpec
        Grid to resample onto.
    nearest : bool
        True: value of the containing cell (0 outside ``grid``); False: bilinear (NaN outside).

    Returns
    -------
    ndarray (target.height, target.width)
        The resampled raster.
    """
    xs, ys = target.cell_centres()
    X, Y = np.meshgrid(xs, ys)
    if nearest:
        return sample_nearest(z, grid, X, Y)
    return sample_bilinear(z, grid, X, Y)


def error_raster(model: np.ndarray, grid: GridSpec, reference: np.ndarray, ref_grid: GridSpec) -> np.ndarray:
    """``model − reference`` on the model's grid (reference resampled bilinearly when the
    grids differ). Raises InputError when the CRSs differ or the grids do not overlap.

    Parameters
    ----------
    model : ndarray (H, W)
        The model DEM (m).
    grid : GridSpec
        Grid of ``model``.
    reference : ndarray
        The reference DEM (m).
    ref_grid : GridSpec
        Grid of ``reference``.

    Returns
    -------
    ndarray (H, W) float32
        Error ``model − reference`` (m); NaN where either has no value.
    """
    if grid.crs != ref_grid.crs:
        raise InputError(f"reference DEM CRS {ref_grid.crs} differs from the model's {grid.crs}")
    ref = reference if ref_grid == grid else resample_to(reference, ref_grid, grid)
    if not np.isfinite(ref).any():
        raise InputError("reference DEM does not overlap the model grid")
    return (model - ref).astype(np.float32)


def stats_by_class(err: np.ndarray, classes: np.ndarray, names: dict[int, str]) -> pd.DataFrame:
    """Error statistics per land-cover class (plus ``all``): columns ``landcover``,
    ``mean_m, median_m, sd_m, rmse_m, nmad_m, p05_m, p95_m, n`` (the caller adds the area share).

    Parameters
    ----------
    err : ndarray (H, W)
        Error raster (m), NaN where unknown.
    classes : ndarray (H, W) int
        Land-cover class code of each cell, on the grid of ``err``.
    names : dict of int to str
        Class code → name (:func:`read_class_names`).

    Returns
    -------
    DataFrame
        One row for ``all`` cells, then one per class of ``names`` present in ``classes``, in code order.
    """
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
                       vertices: Sequence[Sequence[float]], spacing: float, classes: np.ndarray | None = None,
                       class_grid: GridSpec | None = None, vegetation_codes: Sequence[int] = ()) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Sample model and reference along a polyline (Feurer et al. 2018 Fig. 10, Table 5).

    Returns the profile (``distance_m, x_m, y_m, z_model_m, z_ref_m, error_m, vegetation``)
    and the statistics table of the errors for the whole profile and without vegetation
    (rows ``whole``, ``no_vegetation``; columns ``min_m … sd_m, n``).

    Parameters
    ----------
    model : ndarray (H, W)
        The model DEM (m).
    grid : GridSpec
        Grid of ``model``.
    reference : ndarray
        The reference DEM (m).
    ref_grid : GridSpec
        Grid of ``reference``.
    vertices : sequence of [x, y]
        Profile polyline in the site CRS (m), at least two vertices.
    spacing : float
        Sample spacing along the profile (m).
    classes : ndarray int or None
        Land-cover class codes; None: no sample counts as vegetation.
    class_grid : GridSpec or None
        Grid of ``classes``.
    vegetation_codes : sequence of int
        Class codes counted as vegetation (nearest cell).

    Returns
    -------
    profile : DataFrame
        One row per sample; ``error_m`` is ``z_model_m − z_ref_m`` (bilinear samples, m).
    stats : DataFrame
        Statistics of ``error_m`` for the rows ``whole`` and ``no_vegetation``.
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


# --------------------------------------------------------------------------- stage runners


def read_class_names(path: str | Path) -> dict[int, str]:
    """``code, name`` CSV of land-cover classes → {code: name}."""
    path = Path(path)
    try:
        df = pd.read_csv(path)
        return {int(c): str(n) for c, n in zip(df["code"], df["name"])}
    except (OSError, KeyError, ValueError, pd.errors.ParserError) as exc:
        raise InputError(f"{path}: cannot read land-cover classes with columns code, name ({exc})") from None


def codes_of(names: dict[int, str], wanted: Sequence[str]) -> list[int]:
    """Codes of the land-cover classes named in ``wanted``.

    Parameters
    ----------
    names : dict of int to str
        Class code → name (:func:`read_class_names`).
    wanted : sequence of str
        Class names to look up; names not in ``names`` are ignored.

    Returns
    -------
    list of int
        The codes whose name is in ``wanted``, in the order of ``names``.
    """
    return [c for c, n in names.items() if n in set(wanted)]


def checkpoint_figures(errors: pd.DataFrame, hist_png: str | Path, map_png: str | Path, bins: int,
                       limit_m: float, stats: dict[str, float]) -> None:
    """Histogram (Table 3 style annotation) and map of checkpoint errors (diverging colours).

    Parameters
    ----------
    errors : DataFrame
        Checkpoint errors with columns ``x_m, y_m, error_m`` (:func:`checkpoint_errors`).
    hist_png, map_png : path
        Output files of the histogram and the map.
    bins : int
        Number of histogram bins.
    limit_m : float
        Colour scale limit of the map (± m).
    stats : dict
        Error statistics (:func:`error_stats`); ``n, mean, sd, nmad`` go in the histogram title.
    """
    from kitegully.io.figures import map_axes, new_figure, save_figure

    e = errors["error_m"].to_numpy()
    ok = np.isfinite(e)
    fig, ax = new_figure(figsize=(5, 3.5))
    if ok.any():
        ax.hist(e[ok], bins=bins, color="0.4", edgecolor="white")
    ax.axvline(0.0, color="k", lw=0.8)
    ax.set(xlabel="error e = z_DSM − z_checkpoint (m)", ylabel="checkpoints",
           title=f"n = {stats['n']}, mean {stats['mean']:+.3f} m, SD {stats['sd']:.3f} m, NMAD {stats['nmad']:.3f} m")
    save_figure(fig, hist_png)
    fig, ax = new_figure(figsize=(6, 5))
    sc = ax.scatter(errors["x_m"][ok], errors["y_m"][ok], c=e[ok], cmap="RdBu_r", vmin=-limit_m, vmax=limit_m, s=14,
                    edgecolors="k", linewidths=0.2, label="checkpoint")
    if (~ok).any():
        ax.scatter(errors["x_m"][~ok], errors["y_m"][~ok], marker="x", c="0.5", s=12, label="no DSM value")
    fig.colorbar(sc, ax=ax, shrink=0.8, label="error z_DSM − z_checkpoint (m)")
    map_axes(ax)
    # below the map: checkpoints cover the whole site, so no corner of it is free for a legend
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.16), ncol=2, frameon=False)
    ax.set_title("Checkpoint errors of the DSM")
    save_figure(fig, map_png)


def validate_checkpoints(dsm_path: str | Path, checkpoints_path: str | Path, params: CheckpointParams, out: Mapping,
                         landcover_path: str | Path | None = None,
                         classes_path: str | Path | None = None) -> pd.DataFrame:
    """DSM errors at independent checkpoints: error table, summary, histogram and map.

    Parameters
    ----------
    dsm_path, checkpoints_path : path
        The DSM (GeoTIFF, NaN nodata) and the checkpoint table (id, x, y, z in the site CRS).
    params : CheckpointParams
        Parameters.
    out : mapping
        Product name → path; keys errors, summary, histogram, map (and groups with a land cover).
    landcover_path, classes_path : path, optional
        Twin land-cover truth and its class table (evaluation only): also writes
        ``out["groups"]``, statistics for all, bare-ground (``params.bare_classes``) and
        other checkpoints.

    Returns
    -------
    DataFrame
        One row per checkpoint with its error ``error_m`` (DSM − checkpoint).

    Raises
    ------
    InputError
        An all-nodata DSM or an unreadable checkpoint table.
    """
    from kitegully.io.raster import read_raster
    from kitegully.io.tables import write_table

    dsm, grid = read_raster(dsm_path)
    if not np.isfinite(dsm).any():
        raise InputError(f"{dsm_path}: the DSM is all nodata")
    pts = read_checkpoints(checkpoints_path)
    err = checkpoint_errors(dsm, grid, pts)
    if landcover_path is not None:
        lc, lgrid = read_raster(landcover_path)
        names = read_class_names(classes_path)
        codes = sample_nearest(lc, lgrid, err["x_m"].to_numpy(), err["y_m"].to_numpy())
        err["landcover"] = [names.get(int(c), "unknown") for c in codes]
        bare = err["landcover"].isin(list(params.bare_classes)).to_numpy()
        groups = {"all": np.ones(len(err), bool), "bare": bare, "other": ~bare}
        rows = {g: error_stats(err["error_m"].to_numpy()[m]) for g, m in groups.items()}
        tab = pd.DataFrame({"statistic": list(STAT_NAMES), **{f"{g}_m": [rows[g][k] for k in STAT_NAMES] for g in groups}})
        write_table(tab, out["groups"])
    write_table(err, out["errors"])
    stats = error_stats(err["error_m"].to_numpy())
    write_table(summary_table(err["error_m"].to_numpy()), out["summary"])
    n_missing = int(err["error_m"].isna().sum())
    if n_missing:
        import logging

        logging.getLogger(__name__).warning("%d of %d checkpoints fall on DSM nodata or outside it", n_missing, len(err))
    checkpoint_figures(err, out["histogram"], out["map"], params.histogram_bins, params.error_limit_m, stats)
    return err


def auto_profile(centrelines_path: str | Path, length_m: float) -> list[list[float]]:
    """A straight section across the longest gully centreline, centred on its midpoint."""
    from kitegully.io.vectors import read_vector

    gdf = read_vector(centrelines_path)
    if len(gdf) == 0:
        raise InputError(f"{centrelines_path}: no gully centreline to place the profile across")
    line = gdf.geometry.iloc[int(np.argmax(gdf.geometry.length.to_numpy()))]
    L = line.length
    p = line.interpolate(0.5 * L)
    a, b = line.interpolate(0.5 * L - 1.0), line.interpolate(0.5 * L + 1.0)
    t = np.array([b.x - a.x, b.y - a.y])
    t /= np.linalg.norm(t)
    n = np.array([-t[1], t[0]]) * 0.5 * length_m
    return [[p.x - n[0], p.y - n[1]], [p.x + n[0], p.y + n[1]]]


def validate_against_truth(dsm_path: str | Path, truth_dsm_path: str | Path, truth_dtm_path: str | Path,
                           landcover_path: str | Path, classes_path: str | Path, centrelines_path: str | Path,
                           params: TruthParams, out: Mapping) -> dict:
    """Twin only (evaluation): DSM − truth error raster, statistics by land cover, error map
    and the profile comparison (Fig. 10 / Table 5) along the configured or automatic polyline.

    Parameters
    ----------
    dsm_path : path
        The DSM.
    truth_dsm_path, truth_dtm_path, landcover_path, classes_path, centrelines_path : path
        The twin's truth: surface, ground, land cover and its classes, gully centrelines.
    params : TruthParams
        Parameters.
    out : mapping
        Product name → path; keys error_raster, by_landcover, error_map, profile,
        profile_stats, profile_png.

    Returns
    -------
    dict
        Error statistics of DSM − truth DSM over all cells.
    """
    import logging

    from kitegully.io.figures import map_axes, new_figure, save_figure
    from kitegully.io.raster import read_raster, write_raster
    from kitegully.io.tables import write_table

    log = logging.getLogger(__name__)
    dsm, grid = read_raster(dsm_path)
    tdsm, tgrid = read_raster(truth_dsm_path)
    err = error_raster(dsm, grid, tdsm, tgrid)
    write_raster(out["error_raster"], err, grid, tags={"units": "m", "definition": "DSM - truth DSM"})
    lc, lgrid = read_raster(landcover_path)
    names = read_class_names(classes_path)
    lc_on = lc if lgrid == grid else resample_to(lc, lgrid, grid, nearest=True)
    tab = stats_by_class(err, lc_on, names)
    present = [c for c in sorted(names) if (lc_on == c).any()]
    tab.insert(1, "area_pct", [100.0] + [100.0 * float(np.mean(lc_on == c)) for c in present])
    tab.insert(2, "valid_pct", [100.0 * float(np.isfinite(err).mean())] +
               [100.0 * float(np.isfinite(err[lc_on == c]).mean()) for c in present])
    write_table(tab, out["by_landcover"])
    lim = params.error_limit_m
    fig, ax = new_figure(figsize=(7, 5.5))
    step = max(1, int(np.ceil(max(err.shape) / params.figure_max_px)))
    xmin, ymin, xmax, ymax = grid.bounds
    im = ax.imshow(err[::step, ::step], extent=(xmin, xmax, ymin, ymax), cmap="RdBu_r", vmin=-lim, vmax=lim,
                   interpolation="nearest")
    fig.colorbar(im, ax=ax, shrink=0.8, label="DSM − truth DSM (m)")
    map_axes(ax)
    ax.set_title("DSM error against the twin's true surface")
    save_figure(fig, out["error_map"])
    # profile (Feurer et al. 2018 Fig. 10 / Table 5)
    pc = params.profile
    verts = pc.polyline if pc.polyline else auto_profile(centrelines_path, pc.auto_length_m)
    ref_path = truth_dtm_path if pc.reference == "dtm" else truth_dsm_path
    ref, rgrid = read_raster(ref_path)
    prof, ptab = profile_comparison(dsm, grid, ref, rgrid, verts, pc.spacing_m, lc, lgrid,
                                    codes_of(names, list(params.vegetation_classes)))
    write_table(prof, out["profile"])
    write_table(ptab, out["profile_stats"])
    fig, (a1, a2) = new_figure(2, 1, figsize=(7, 5), sharex=True)
    a1.plot(prof["distance_m"], prof["z_ref_m"], "k-", lw=1.2, label=f"truth {pc.reference.upper()}")
    a1.plot(prof["distance_m"], prof["z_model_m"], "-", color="tab:orange", lw=1.0, label="kite DSM")
    v = prof["vegetation"].to_numpy()
    if v.any():
        a1.plot(prof["distance_m"][v], prof["z_model_m"][v], ".", color="tab:green", ms=3, label="vegetation")
    a1.set_ylabel("elevation (m)")
    a1.legend(loc="best")
    a2.plot(prof["distance_m"], prof["error_m"], "-", color="tab:red", lw=0.8)
    a2.axhline(0, color="k", lw=0.6)
    a2.set(xlabel="distance along profile (m)", ylabel="DSM − reference (m)")
    a1.set_title("Profile across a gully (cf. Feurer et al. 2018 Fig. 10)")
    save_figure(fig, out["profile_png"])
    s = error_stats(err)
    log.info("DSM - truth: mean %+.3f m, SD %.3f m, NMAD %.3f m over %d cells", s["mean"], s["sd"], s["nmad"], s["n"])
    return s
