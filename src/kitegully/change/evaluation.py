"""Evaluation of the change stage against known change (twins; evaluation only, reads truth).

* ``detection``: cells whose true change exceeds 2 σ_DoD, detected (same sign) or missed per
  threshold method; false detections on cells without true change (|Δ| < 1 mm), as a share of
  that stable area.
* budgets against the true net volume of each mask.
* headcut retreat against the true retreat of the nearest true head.
* Moritani et al. (2010): mean lowering per square plot, measured A against true M,
  ``MAE = mean |M − A|``, ``MRE = mean |M − A|/M``, through-origin slope ``b = ΣAM/ΣM²``.
"""

from __future__ import annotations

import logging
from typing import Any, Mapping, Sequence

import numpy as np
import pandas as pd

from kitegully.change import budget as bg
from kitegully.change.dod import resample
from kitegully.change.params import THRESHOLD_METHODS
from kitegully.io.raster import Raster
from kitegully.io.tables import write_table
from kitegully.io.vectors import read_vector

log = logging.getLogger(__name__)

NO_CHANGE_M = 1e-3


def detection_table(dod: np.ndarray, sigma: np.ndarray, true: np.ndarray, detected: Mapping[str, np.ndarray]) -> pd.DataFrame:
    """Detected / missed / false counts per method (see module docstring).

    Parameters
    ----------
    dod : ndarray (H, W)
        Measured DoD (m).
    sigma : ndarray (H, W)
        σ_DoD (m).
    true : ndarray (H, W)
        True change, epoch 2 − epoch 1 (m).
    detected : mapping
        Method name to its ndarray (H, W) bool of detected cells.

    Returns
    -------
    DataFrame
        One row per method: ``method``, ``true_change_cells``, ``detected``, ``missed``, ``detection_rate``,
        ``stable_cells``, ``false``, ``false_rate``.
    """
    ok = np.isfinite(dod) & np.isfinite(true) & np.isfinite(sigma)
    big = ok & (np.abs(true) > 2 * sigma)
    still = ok & (np.abs(true) < NO_CHANGE_M)
    rows = []
    for m, det in detected.items():
        hit = big & det & (np.sign(dod) == np.sign(true))
        false = still & det
        rows.append(dict(method=m, true_change_cells=int(big.sum()), detected=int(hit.sum()),
                         missed=int(big.sum() - hit.sum()), detection_rate=hit.sum() / max(big.sum(), 1),
                         stable_cells=int(still.sum()), false=int(false.sum()), false_rate=false.sum() / max(still.sum(), 1)))
    return pd.DataFrame(rows)


def moritani_plots(dod: np.ndarray, true: np.ndarray, cell: float, plot_m: float, min_lowering_m: float,
                   min_coverage: float = 0.8) -> tuple[pd.DataFrame, dict[str, float]]:
    """Mean lowering per square plot (measured A, true M) and MAE, MRE, b over eroding plots.

    Parameters
    ----------
    dod : ndarray (H, W)
        Measured DoD (m).
    true : ndarray (H, W)
        True change (m).
    cell : float
        Cell size (m).
    plot_m : float
        Side of a plot (m), rounded to whole cells; a partial plot at the grid's edge is dropped.
    min_lowering_m : float
        Least true mean lowering of a kept plot (m).
    min_coverage : float
        Least share of a kept plot's cells where both ``dod`` and ``true`` are finite.

    Returns
    -------
    plots : DataFrame
        One row per kept plot: ``plot_row``, ``plot_col``, ``true_lowering_m``, ``measured_lowering_m``, ``coverage``.
    summary : dict
        ``plots``, ``plot_m``, ``mae_m``, ``mre_pct`` and ``b`` (no ``plot_m`` and NaN values when no plot is kept).
    """
    k = max(1, int(round(plot_m / cell)))
    H, W = (dod.shape[0] // k) * k, (dod.shape[1] // k) * k

    def blocks(a):
        return a[:H, :W].reshape(H // k, k, W // k, k).swapaxes(1, 2).reshape(H // k, W // k, k * k)

    d, t = blocks(dod), blocks(true)
    ok = np.isfinite(d) & np.isfinite(t)
    cov = ok.mean(axis=2)
    with np.errstate(invalid="ignore"):
        A = -np.nansum(np.where(ok, d, 0), axis=2) / ok.sum(axis=2)
        M = -np.nansum(np.where(ok, t, 0), axis=2) / ok.sum(axis=2)
    keep = (cov >= min_coverage) & (M >= min_lowering_m)
    r, c = np.nonzero(keep)
    df = pd.DataFrame(dict(plot_row=r, plot_col=c, true_lowering_m=M[keep], measured_lowering_m=A[keep], coverage=cov[keep]))
    if len(df) == 0:
        return df, dict(plots=0, mae_m=np.nan, mre_pct=np.nan, b=np.nan)
    e = np.abs(df["true_lowering_m"] - df["measured_lowering_m"])
    m = df["true_lowering_m"].to_numpy()
    summary = dict(plots=len(df), plot_m=k * cell, mae_m=float(e.mean()), mre_pct=float(100 * np.mean(e / m)),
                   b=float(np.sum(df["measured_lowering_m"] * m) / np.sum(m * m)))
    return df, summary


def headcut_table(measured: pd.DataFrame, true1: pd.DataFrame, true2: pd.DataFrame, max_dist_m: float) -> pd.DataFrame:
    """Measured retreat beside the true retreat of the nearest true epoch-1 head (gully_id, retreat_m).

    Parameters
    ----------
    measured : DataFrame
        Measured heads: ``x_digitised``, ``y_digitised``, ``retreat_m`` and optionally ``retreat_mid_m``,
        ``retreat_dod_m``.
    true1 : GeoDataFrame
        True epoch-1 heads (points) with ``gully_id``.
    true2 : DataFrame
        True epoch-2 heads with ``gully_id`` and ``retreat_m``.
    max_dist_m : float
        Farthest a true head may lie from a digitised head (m).

    Returns
    -------
    DataFrame
        ``measured`` plus ``true_gully_id``, ``digitising_offset_m``, ``true_retreat_m``, ``error_m`` (and
        ``error_mid_m``, ``error_dod_m`` beside their estimates); NaN where no true head is near enough.
    """
    out = measured.copy()
    tx, ty = true1.geometry.x.to_numpy(), true1.geometry.y.to_numpy()
    ret = dict(zip(true2["gully_id"], true2["retreat_m"]))
    gid, dist, tr = [], [], []
    for x, y in zip(out["x_digitised"], out["y_digitised"]):
        d = np.hypot(tx - x, ty - y)
        i = int(np.argmin(d)) if d.size else -1
        if i < 0 or d[i] > max_dist_m:
            gid.append(np.nan), dist.append(np.nan), tr.append(np.nan)
            continue
        g = true1["gully_id"].iloc[i]
        gid.append(g), dist.append(float(d[i])), tr.append(float(ret.get(g, np.nan)))
    out["true_gully_id"], out["digitising_offset_m"], out["true_retreat_m"] = gid, dist, tr
    out["error_m"] = out["retreat_m"] - out["true_retreat_m"]
    for k in ("mid", "dod"):
        if f"retreat_{k}_m" in out:
            out[f"error_{k}_m"] = out[f"retreat_{k}_m"] - out["true_retreat_m"]
    return out


def headcut_rows(ht: pd.DataFrame) -> list[tuple[str, float, str]]:
    """Summary rows: n, median and 90th percentile of |error| for heads that retreated (true > 0) and stable heads
    (true = 0: false retreat), for the stated estimate and the half-height and DoD-reach estimates beside it."""
    rows: list[tuple[str, float, str]] = []
    if "true_retreat_m" not in ht or "error_m" not in ht:
        return rows
    for label, sel in (("heads that retreated", ht["true_retreat_m"] > 0), ("stable heads", ht["true_retreat_m"] == 0)):
        for k, name in (("", "lip, stated"), ("_mid", "half height"), ("_dod", "DoD reach")):
            col = f"error{k}_m"
            if col not in ht:
                continue
            e = ht.loc[sel & ht[col].notna(), col].abs()
            rows += [(f"headcut |error| n, {label}, {name}", float(len(e)), "count"),
                     (f"headcut |error| median, {label}, {name}", float(e.median()) if len(e) else np.nan, "m"),
                     (f"headcut |error| p90, {label}, {name}", float(e.quantile(0.9)) if len(e) else np.nan, "m")]
    return rows


def _headcut_ceiling(t1: Raster, t2: Raster, grid, spec: tuple[str, Any], true_heads1: str, true_heads2: str,
                     cfg: Mapping[str, Any], path: str) -> list[tuple[str, float, str]]:
    """The headcut measurement on the true surfaces (evaluation only); its table and summary rows."""
    from kitegully.change.headcuts import measure_headcut_retreat
    from kitegully.change.stage import read_heads
    heads_path, params = spec
    ref = measure_headcut_retreat(resample(t1, grid), resample(t2, grid), grid, read_heads(heads_path), params)
    rt = headcut_table(ref, read_vector(true_heads1), read_vector(true_heads2), cfg["head_match_m"])
    write_table(rt, path)
    rows = []
    for label, sel in (("heads that retreated", rt["true_retreat_m"] > 0), ("stable heads", rt["true_retreat_m"] == 0)):
        e = rt.loc[sel & rt["error_m"].notna(), "error_m"].abs()
        rows += [(f"headcut |error| n, {label}, lip, method on the true surfaces", len(e), "count"),
                 (f"headcut |error| median, {label}, lip, method on the true surfaces", float(e.median()) if len(e) else np.nan, "m")]
    return rows


def evaluate_change(dod_path: str, sigma_path: str, thresholded: Mapping[str, str], truth1: str, truth2: str,
                    masks: Sequence[Mapping[str, Any]], budget_csv: str, headcuts_csv: str,
                    true_heads1: str | None, true_heads2: str | None, cfg: Mapping[str, Any],
                    out: Mapping[str, str], widening: tuple | None = None,
                    headcut_ceiling: tuple[str, Any] | None = None) -> dict[str, Any]:
    """Write detection.csv, budget_vs_truth.csv, headcut_retreat_vs_truth.csv, moritani tables and a summary.

    ``cfg``: ``plot_m`` and ``min_lowering_m`` (Moritani plots), ``head_match_m``,
    ``net_tolerance`` (target, fraction of the true net volume). ``widening``:
    ``(widening_csv, true_polygons1, true_polygons2, margin_m, sections_gpkg)`` → ``out["widening_vs_truth"]``
    (true width = the extended section line's length inside the true polygons of each epoch).
    ``headcut_ceiling``: ``(digitised_heads_gpkg, ChangeParams)``: the headcut measurement run
    once more on the two TRUE surfaces (``truth1``, ``truth2``) from the same digitised heads →
    ``out["headcuts_on_truth"]`` and summary rows: what the method measures where the surfaces
    resolve every head, beside what it measures on the photogrammetric DEMs (the split of
    the error between method and DEM).

    Parameters
    ----------
    dod_path, sigma_path : str
        The stage's DoD and σ_DoD rasters.
    thresholded : mapping
        Threshold method name to its thresholded DoD raster (finite and non-zero: detected).
    truth1, truth2 : str
        True surfaces of epoch 1 and epoch 2 (rasters).
    masks : sequence of mapping
        Budget mask specs, as given to the stage.
    budget_csv, headcuts_csv : str
        The stage's budget and headcut tables.
    true_heads1, true_heads2 : str or None
        True heads of each epoch (vector files); None leaves the true retreat NaN.
    cfg : mapping
        See above.
    out : mapping
        Output paths by key: ``detection``, ``budget_vs_truth``, ``headcuts_vs_truth``, ``moritani_plots``,
        ``summary`` and, when written, ``headcuts_on_truth`` and ``widening_vs_truth``.
    widening : tuple or None
        See above; None writes no widening table.
    headcut_ceiling : tuple or None
        See above; None skips the run on the true surfaces.

    Returns
    -------
    dict
        The summary table as quantity to value.
    """

    dod_r = Raster.read(dod_path)
    dod, grid = dod_r.data, dod_r.grid
    sigma = Raster.read(sigma_path).data
    t1, t2 = Raster.read(truth1), Raster.read(truth2)
    true = resample(t2, grid) - resample(t1, grid)
    detected = {m: np.isfinite(a := Raster.read(thresholded[m]).data) & (a != 0) for m in THRESHOLD_METHODS}
    det = detection_table(dod, sigma, true, detected)
    write_table(det, out["detection"])

    budget = pd.read_csv(budget_csv)
    groups = bg.mask_groups(masks, grid)
    ok = np.isfinite(dod) & np.isfinite(true)
    tn = {g.name: float(np.sum(g.block(true)[g.local & g.block(ok)]) * grid.cell**2) for g in groups}
    budget["true_net_m3"] = budget["mask"].map(tn)
    budget["error_m3"] = budget["net_m3"] - budget["true_net_m3"]
    budget["error_pct"] = 100 * budget["error_m3"] / budget["true_net_m3"].abs()
    budget["within_1sd"] = budget["error_m3"].abs() <= budget["net_sd_m3"]
    budget["within_2sd"] = budget["error_m3"].abs() <= 2 * budget["net_sd_m3"]
    write_table(budget, out["budget_vs_truth"])

    heads = pd.read_csv(headcuts_csv)
    if true_heads1 and true_heads2 and len(heads):
        ht = headcut_table(heads, read_vector(true_heads1), read_vector(true_heads2), cfg["head_match_m"])
    else:
        ht = heads.assign(true_retreat_m=np.nan, error_m=np.nan)
    write_table(ht, out["headcuts_vs_truth"])
    ceiling_rows = []
    if headcut_ceiling is not None and true_heads1 and true_heads2 and "headcuts_on_truth" in out:
        ceiling_rows = _headcut_ceiling(t1, t2, grid, headcut_ceiling, true_heads1, true_heads2, cfg, out["headcuts_on_truth"])
    elif "headcuts_on_truth" in out:  # no digitised or true heads: an empty table with the columns
        write_table(ht.iloc[0:0], out["headcuts_on_truth"])

    plots_df, mor = moritani_plots(dod, true, grid.cell, cfg["plot_m"], cfg["min_lowering_m"])
    write_table(plots_df, out["moritani_plots"])

    wrows = []
    if widening is not None and "widening_vs_truth" in out:
        wcsv, p1, p2, margin, secs = widening
        wt = pd.read_csv(wcsv)
        if p1 and p2 and secs and len(wt):
            from kitegully.change.widening import true_widths
            sec = read_vector(secs, crs=grid.crs)
            wt["true_width1_m"] = true_widths(sec, read_vector(p1, crs=grid.crs), margin)[wt["section_id"]]
            wt["true_width2_m"] = true_widths(sec, read_vector(p2, crs=grid.crs), margin)[wt["section_id"]]
            wt["true_widening_m"] = wt["true_width2_m"] - wt["true_width1_m"]
            wt["error_m"] = wt["widening_m"] - wt["true_widening_m"]
            ok = wt["error_m"].notna()
            mov = ok & (wt["true_widening_m"] > 0.1)
            wrows = [("widening sections measured on both DEMs", int(ok.sum()), "count"),
                     ("widening sections, all", len(wt), "count"),
                     ("widening median |error|, all measured sections", float(wt.loc[ok, "error_m"].abs().median()), "m"),
                     ("widening median error (bias), all measured sections", float(wt.loc[ok, "error_m"].median()), "m"),
                     ("widening sections that truly widened > 0.1 m", int(mov.sum()), "count"),
                     ("widening median |error|, sections that widened", float(wt.loc[mov, "error_m"].abs().median()) if mov.any() else np.nan, "m"),
                     ("widening mean measured vs true, measured sections", float(wt.loc[ok, "widening_m"].mean()) - float(wt.loc[ok, "true_widening_m"].mean()), "m")]
        write_table(wt, out["widening_vs_truth"])
    site = budget[(budget["mask"] == "site") & (budget["method"] == "raw")].iloc[0]
    hc = ht[np.isfinite(ht["error_m"])] if "error_m" in ht else ht.iloc[0:0]
    hc_moving = hc[hc["true_retreat_m"] > 0] if len(hc) else hc
    prob = det.set_index("method").loc["probabilistic"]
    rows = [
        ("site_net_m3", site["net_m3"], "m3"), ("site_true_net_m3", site["true_net_m3"], "m3"),
        ("site_net_sd_m3 (stated: correlated + co-registration)", site["net_sd_m3"], "m3"),
        ("site_net_sd_m3 (correlated)", site["net_sd_correlated_m3"], "m3"),
        ("site_net_sd_m3 (co-registration offset)", site.get("net_sd_coregistration_m3", np.nan), "m3"),
        ("site_net_sd_m3 (independent)", site["net_sd_independent_m3"], "m3"),
        ("site_net_error_pct", site["error_pct"], "%"),
        ("target: |net error| <= %g %% of truth" % (100 * cfg["net_tolerance"]), float(abs(site["error_pct"]) <= 100 * cfg["net_tolerance"]), "1 = met"),
        ("target: truth within stated 1 sd", float(site["within_1sd"]), "1 = met"),
        ("truth within stated 2 sd", float(site["within_2sd"]), "1 = yes"),
        ("headcuts matched", len(hc), "count"),
        ("headcut median |error| (all matched heads)", float(hc["error_m"].abs().median()) if len(hc) else np.nan, "m"),
        ("headcut median |error| (heads that retreated)", float(hc_moving["error_m"].abs().median()) if len(hc_moving) else np.nan, "m"),
        # the target is over heads that really retreated: a stable head measured 0 says nothing about retreat
        ("target: headcut median |error| <= 0.5 m (heads that retreated)",
         float(len(hc_moving) > 0 and hc_moving["error_m"].abs().median() <= 0.5), "1 = met"),
        *headcut_rows(ht),
        *ceiling_rows,
        ("false detection rate on unchanged cells, 95 %", float(prob["false_rate"]) * 100, "%"),
        ("target: false detections <= 5 % at 95 %", float(prob["false_rate"] <= 0.05), "1 = met"),
        ("detection rate of change > 2 sigma, 95 %", float(prob["detection_rate"]) * 100, "%"),
        ("moritani plots", mor["plots"], "count"), ("moritani MAE", mor.get("mae_m", np.nan), "m"),
        ("moritani MRE", mor.get("mre_pct", np.nan), "%"), ("moritani b", mor.get("b", np.nan), "-"),
        *wrows,
    ]
    summary = pd.DataFrame(rows, columns=["quantity", "value", "unit"])
    write_table(summary, out["summary"])
    log.info("evaluation:\n%s", summary.to_string(index=False))
    return dict(zip(summary["quantity"], summary["value"]))
