"""The change stage: two epoch DEMs in; DoD, thresholds, budgets, headcuts and figures out.

:func:`detect_change` is the entry point; its parameters are :class:`ChangeParams`.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping, Sequence

import numpy as np
import pandas as pd

from kitegully import InputError
from kitegully.change import budget as bg
from kitegully.change import plots, uncertainty as unc
from kitegully.change.coregister import above_ground, coregister
from kitegully.evaluate.dem import nmad
from kitegully.change.dod import dem_of_difference, load_epoch, matching_voids, on_common_grid
from kitegully.change.error_model import SIGMA_FACTOR_TAG, checkpoint_cells, heteroscedastic_sigma
from kitegully.change.headcuts import COLUMNS as HEADCUT_COLUMNS, measure_headcut_retreat
from kitegully.change.params import OUTPUT_FILES, THRESHOLD_METHODS, ChangeParams  # noqa: F401  (ChangeParams re-exported)
from kitegully.change.widening import COLUMNS as WIDENING_COLUMNS, measure_widening
from kitegully.io.raster import Raster
from kitegully.io.tables import write_table
from kitegully.io.vectors import read_vector

if TYPE_CHECKING:
    from kitegully.change.coregister import Coregistration
    from kitegully.io.raster import GridSpec

log = logging.getLogger(__name__)

def output_paths(folder: str | Path) -> dict[str, str]:
    """:func:`detect_change`'s ``out`` for writing its products under ``folder`` (created) with the rule's file names."""
    Path(folder).mkdir(parents=True, exist_ok=True)
    return {k: str(Path(folder) / v) for k, v in OUTPUT_FILES.items()}


def read_heads(path: str) -> pd.DataFrame:
    """Digitised heads (points) as ``head_id, x, y``; ids from a ``head_id``/``id`` column or the row number."""
    gdf = read_vector(path)
    if len(gdf) and not (gdf.geom_type == "Point").all():
        raise InputError(f"{path}: gully heads must be points, got {sorted(set(gdf.geom_type))}")
    ids = gdf["head_id"] if "head_id" in gdf.columns else gdf["id"] if "id" in gdf.columns else pd.Series(range(1, len(gdf) + 1))
    return pd.DataFrame({"head_id": np.asarray(ids), "x": gdf.geometry.x.to_numpy(), "y": gdf.geometry.y.to_numpy()})


def detect_change(epochs: Sequence[Mapping[str, Any]], masks: Sequence[Mapping[str, Any]], heads_path: str | None,
                  params: ChangeParams, out: Mapping[str, str], site_crs: str | None = None,
                  figure: Mapping[str, Any] | None = None, attribution: str | None = None,
                  sections_path: str | None = None) -> dict[str, Any]:
    """Co-register, difference, threshold and budget two epochs; write every product.

    Parameters
    ----------
    epochs
        Two epoch specs (older first): ``name, dem, nodata, accuracy``.
    masks
        Budget mask specs: ``name, file, kind, by, classes, values, unstable, stable``
        (:func:`kitegully.change.budget.stable_candidates`).
    heads_path
        GeoPackage of heads digitised at epoch 1, or None.
    params : ChangeParams
    out
        Output paths by key (:data:`kitegully.change.params.OUTPUTS` and ``thresholded_<method>``).
    site_crs
        The DEMs must be in this CRS.
    figure
        ``limit_m`` (colour/histogram range) and ``max_px``.
    sections_path
        Epoch-1 cross-sections (the polygons stage's ``cross_sections.gpkg``) whose width is
        measured on both DEMs (``widening.csv``), or None (an empty table).

    Returns
    -------
    dict
        Summary numbers (co-registration, σ, whole-site raw budget, timings).
    """
    t0 = time.perf_counter()
    if len(epochs) != 2:
        raise InputError(f"change.epochs: exactly two epochs are needed, got {len(epochs)}")
    e1, e2 = (load_epoch(s, f"change.epochs[{i}]", site_crs) for i, s in enumerate(epochs))
    grid, z1, z2_raw = on_common_grid(e1, e2)
    groups = bg.mask_groups(masks, grid)
    unstable = bg.unstable_union(masks, groups, z1.shape)
    voids = matching_voids((e1, e2), grid, params.min_correlation, params.void_margin_m,
                           valid=np.isfinite(z1) & np.isfinite(z2_raw))
    del z2_raw
    stable = np.isfinite(z1) & ~voids & bg.stable_candidates(masks, groups, z1.shape, unstable)
    if params.stable_max_object_height_m is not None:
        objects = above_ground(z1, grid.cell, params.stable_object_window_m, params.stable_max_object_height_m)
        log.info("above-ground objects (> %.2f m): %.1f %% of the grid, left out of stable ground",
                 params.stable_max_object_height_m, 100.0 * objects.mean())
        stable &= ~objects
    inside = [m["name"] for m in masks if m.get("stable")]
    log.info("stable ground: %.1f %% of the common grid%s", 100.0 * stable.mean(),
             f" (inside the masks flagged stable only: {', '.join(inside)})" if inside else "")
    z2, coreg = coregister(z1, e2.dem, grid, stable, params)
    dod = dem_of_difference(z1, z2)
    n_void = int((voids & np.isfinite(dod)).sum())
    dod[voids] = np.nan
    stable &= np.isfinite(dod)
    s1, i1 = unc.epoch_sigma(e1, grid, params.checkpoint_outlier_nmad)
    s2, i2 = unc.epoch_sigma(e2, grid, params.checkpoint_outlier_nmad)
    sigma = unc.propagate(s1, s2, dod.shape)
    sigma_rows = [i1, i2]
    if params.heteroscedastic:
        sigma, row = heteroscedastic_sigma(sigma, z1, dod, np.isfinite(z1) & ~unstable & ~voids, grid.cell,
                                          params.headcut_window_m, params.stable_object_window_m,
                                          checkpoint_cells((e1, e2), grid))
        sigma_rows.append(row)
    detected = unc.detect(dod, sigma, params)

    Raster(dod, grid).write(out["dod"], tags={"units": "m", "definition": "DEM2 (co-registered) - DEM1"})
    Raster(sigma, grid).write(out["sigma_dod"], tags={"units": "m", "definition": "sqrt(s1^2 + s2^2)" + (
        SIGMA_FACTOR_TAG if params.heteroscedastic else "")})
    Raster(stable.astype(np.uint8), grid, 255).write(out["stable"], tags={"definition": "1 = stable ground used for co-registration"})
    for m in THRESHOLD_METHODS:
        Raster(unc.thresholded(dod, detected[m]), grid).write(out[f"thresholded_{m}"], tags={"units": "m", "threshold": m})

    vg, coreg_sd = uncertainty_model(dod, sigma, stable, grid, params, out, attribution)
    coreg.offset_sd_m = coreg_sd
    budget = bg.compute_budgets(dod, sigma, detected, groups, grid.cell, vg, coreg_sd)
    return write_products(budget, coreg, sigma_rows, sigma, n_void, grid, z1, z2, dod, stable, heads_path, sections_path,
                          params, out, [g.name for g in groups if ":" not in g.name], figure, attribution, t0)


def uncertainty_model(dod: np.ndarray, sigma: np.ndarray, stable: np.ndarray, grid: GridSpec, params: ChangeParams,
                      out: Mapping[str, str], attribution: str | None = None) -> tuple[Any, float]:
    """Variogram of dh/σ on stable ground (table and figure written) and the co-registration offset SD.

    Returns ``(variogram or None, offset SD m)``. Needs the whole site's arrays (the stable
    cells' median and NMAD, random pairs over the site). O(cells · log 64 + samples²).

    Parameters
    ----------
    dod : ndarray (H, W)
        DoD (m).
    sigma : ndarray (H, W)
        σ_DoD (m).
    stable : ndarray (H, W) bool
        Stable ground; cells beyond ``coreg_outlier_nmad`` NMAD of the median dh/σ are left out.
    grid : GridSpec
        The common grid.
    params : ChangeParams
        Reads the ``variogram_*`` keys, ``coreg_outlier_nmad``, ``coreg_enabled`` and ``seed``.
    out : mapping
        Output paths by key; writes ``variogram`` and ``variogram_png``.
    attribution : str or None
        Data attribution printed on the figure; None prints none.

    Returns
    -------
    vg : Variogram or None
        The fitted variogram of dh/σ; None when the fit failed.
    coreg_sd : float
        SD of the co-registration offset (m); 0 without a variogram or with co-registration off.
    """
    zs = dod / sigma
    ok = stable & np.isfinite(zs)
    med, sd = float(np.median(zs[ok])), nmad(zs[ok])
    ok &= np.abs(zs - med) <= params.coreg_outlier_nmad * sd
    vg = None
    try:
        emp = bg.empirical_variogram(zs, grid, ok, params.variogram_max_lag_m, params.variogram_bins,
                                     params.variogram_samples, params.seed)
        vg = bg.fit_variogram(emp, grid.cell, params.variogram_max_lag_m)
        log.info("variogram of dh/sigma: %s", vg.describe())
        if vg.ranges_m and max(vg.ranges_m) >= 0.99 * params.variogram_max_lag_m:
            log.warning("variogram of dh/sigma: its longest range reached change.budget.variogram_max_lag_m (%.0f m): the "
                        "errors may be correlated farther, and the volume uncertainty may be too small; half the site's "
                        "diagonal is the longest lag a whole-site budget needs", params.variogram_max_lag_m)
        write_table(emp.assign(model=vg.model(emp["lag_m"].to_numpy()), fitted_model=vg.describe()), out["variogram"])
    except (ValueError, RuntimeError) as exc:
        log.warning("variogram not fitted (%s): correlated uncertainty left out", exc)
        write_table(pd.DataFrame(columns=["lag_m", "semivariance", "pairs", "model"]), out["variogram"])
    plots.plot_variogram(vg, out["variogram_png"], attribution)

    coreg_sd = 0.0
    if vg is not None and params.coreg_enabled:
        rr, cc = np.nonzero(ok)
        rho = bg.mean_correlation(rr, cc, grid.cell, vg, params.variogram_samples, params.seed)
        coreg_sd = float(np.nanmean(sigma[ok]) * np.sqrt(rho))
        log.info("co-registration offset SD %.4f m (mean correlation of stable pairs %.4f)", coreg_sd, rho)
    return vg, coreg_sd


def write_products(budget: pd.DataFrame, coreg: Coregistration, sigma_rows: list, sigma: np.ndarray, n_void: int,
                   grid: GridSpec, z1: np.ndarray, z2: np.ndarray, dod: np.ndarray, stable: np.ndarray,
                   heads_path: str | None, sections_path: str | None, params: ChangeParams, out: Mapping[str, str],
                   top_masks: list[str], figure: Mapping[str, Any] | None, attribution: str | None,
                   t0: float) -> dict[str, Any]:
    """The stage's tables (budget, co-registration, σ, thresholds, headcuts, widening) and figures; the summary.

    ``budget`` is :func:`kitegully.change.budget.compute_budgets`'s table; ``top_masks`` the
    budget masks without their ``:value`` rows (the bar figure's groups).

    Parameters
    ----------
    budget : DataFrame
        See above.
    coreg : Coregistration
        The applied co-registration.
    sigma_rows : list
        Rows of the σ table (dicts): each epoch's σ and, if applied, the heteroscedastic factor.
    sigma : ndarray (H, W)
        σ_DoD (m).
    n_void : int
        Cells with a DoD left out as matching voids.
    grid : GridSpec
        The common grid.
    z1, z2 : ndarray (H, W)
        Epoch-1 and co-registered epoch-2 DEMs (m).
    dod : ndarray (H, W)
        DoD (m).
    stable : ndarray (H, W) bool
        Stable ground.
    heads_path : str or None
        Heads digitised at epoch 1; None writes an empty headcut table.
    sections_path : str or None
        Epoch-1 cross-sections; None writes an empty widening table.
    params : ChangeParams
        The stage's parameters.
    out : mapping
        Output paths by key (:data:`kitegully.change.params.OUTPUTS`).
    top_masks : list of str
        See above.
    figure : mapping or None
        ``limit_m`` and ``max_px`` of the figures (default 1.0 m and 1500 px).
    attribution : str or None
        Data attribution printed on the figures; None prints none.
    t0 : float
        :func:`time.perf_counter` at the stage's start (s).

    Returns
    -------
    dict
        Summary numbers: shift and offset, stable-ground NMAD before and after, median σ_DoD,
        whole-site raw net volume and its SD, void area and seconds.
    """

    write_table(budget, out["budget"])
    write_table(coreg.table(), out["coregistration"])
    sig_tab = unc.sigma_table(sigma_rows, sigma)
    sig_tab["void_area_m2"] = np.where(sig_tab["epoch"] == "DoD", n_void * grid.cell**2, np.nan)  # low-NCC cells left out
    write_table(sig_tab, out["sigma"])
    write_table(unc.threshold_table(params, sigma), out["thresholds"])
    if heads_path:
        lowering = max(params.headcut_min_incision_m, unc.z_of_confidence(params.confidence) * float(np.nanmedian(sigma)))
        heads = measure_headcut_retreat(z1, z2, grid, read_heads(heads_path), params, lowering_m=lowering)
    else:
        heads = pd.DataFrame(columns=HEADCUT_COLUMNS)
    write_table(heads, out["headcuts"])
    if sections_path:
        secs = read_vector(sections_path, crs=grid.crs)
        wid = measure_widening(z1, z2, grid, secs, params.widening_margin_m, params.widening_min_depth_m, params.widening_end_m)
    else:
        wid = pd.DataFrame(columns=WIDENING_COLUMNS)
    write_table(wid, out["widening"])

    fig = {"limit_m": 1.0, "max_px": 1500, **(figure or {})}
    plots.plot_dod_map(dod, grid, out["dod_map"], fig["limit_m"], fig["max_px"], attribution=attribution)
    plots.plot_budget_bars(budget, out["budget_bars"], masks=top_masks, attribution=attribution)
    lod95 = unc.z_of_confidence(params.confidence) * float(np.nanmedian(sigma))
    plots.plot_histogram(dod, stable, out["histogram"], fig["limit_m"], lod95, attribution=attribution)
    site = budget[(budget["mask"] == "site") & (budget["method"] == "raw")].iloc[0]
    summary = dict(dx_m=coreg.dx_m, dy_m=coreg.dy_m, dz_m=coreg.dz_m, stable_nmad_before_m=coreg.before["nmad_m"],
                   stable_nmad_after_m=coreg.after["nmad_m"], sigma_dod_m=float(np.nanmedian(sigma)),
                   net_m3=float(site["net_m3"]), net_sd_m3=float(site["net_sd_m3"]), void_area_m2=n_void * grid.cell**2,
                   seconds=time.perf_counter() - t0)
    log.info("change detected in %.1f s: whole-site net %.1f ± %.1f m³", summary["seconds"], summary["net_m3"], summary["net_sd_m3"])
    return summary
