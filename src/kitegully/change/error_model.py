"""Heteroscedastic DoD error: how the spread of elevation differences grows with the terrain.

A DSM from dense matching is least precise where the surface is steep or sharply curved and
where it is not the ground: gully walls and rims, shrub and tree crowns, buildings (the
matching window smooths them, wind moves the crowns, and the two epochs' views see them
differently). The checkpoints that give each epoch's σ sit on open, nearly level ground, so a
uniform σ from them under-states the DoD's noise there, and thresholds at 1.96 σ flag such
unchanged cells as change. After Hugonnet et al. (2022; xDEM's
``infer_heteroscedasticity_from_stable``) the DoD's spread is binned by terrain predictors on
ground that has not changed (outside every unstable mask; plants included, they are part of the
noise), and each cell's σ_DoD is the propagated checkpoint σ times the ratio of its bin's NMAD to
the NMAD of the bins the checkpoints fall in, the terrain that σ was measured on (of all unchanged
cells when no epoch has checkpoints; at least 1: the checkpoints' σ is the floor). The
predictors are the epoch-1 DEM's slope and curvature (Hugonnet's) and its height above the
ground surface (what stands on the ground: crowns, whose DSM error slope and curvature at the
matching window's scale only partly show).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd
from scipy import ndimage

from kitegully.change.coregister import height_above_ground

log = logging.getLogger(__name__)

#: Predictor names, in the order of :func:`terrain_predictors`.
PREDICTORS = ("slope_deg", "curvature_per_m", "height_above_ground_m")


def terrain_predictors(z: np.ndarray, cell: float, window_m: float, object_window_m: float,
                       fill: float | None = None) -> list[np.ndarray]:
    """Slope (degrees), |Laplacian curvature| (1/m) and height above the ground (m) of ``z``.

    Slope and curvature are read on ``z`` box-smoothed over ``window_m`` (the DEM's horizontal
    resolution, the matching window: finer relief is noise); the height above the ground is
    :func:`kitegully.change.coregister.height_above_ground` over ``object_window_m`` (the
    change stage's object filter window). NaN cells take ``fill`` (default the highest
    elevation) for the filters and stay NaN. O(cells · object window).
    """
    ok = np.isfinite(z)
    zf = np.where(ok, z, (np.nanmax(z) if ok.any() else 0.0) if fill is None else fill).astype(np.float64)
    k = max(1, int(round(window_m / cell)))
    zs = ndimage.uniform_filter(zf, k, mode="nearest") if k > 1 else zf
    gy, gx = np.gradient(zs, cell)
    slope = np.degrees(np.arctan(np.hypot(gx, gy)))
    curv = np.abs(ndimage.laplace(zs, mode="nearest")) / (cell * cell)
    height = height_above_ground(zf, cell, object_window_m)
    out = []
    for v in (slope, curv, height):
        v = v.astype(np.float32)
        v[~ok] = np.nan
        out.append(v)
    return out


@dataclass
class ErrorModel:
    """NMAD of the DoD per bin of the predictors on unchanged ground and the factor it gives each cell."""

    edges: list[np.ndarray]
    nmad: np.ndarray  # one axis per predictor, empty bins filled
    count: np.ndarray
    reference_nmad: float

    def _index(self, predictors: list[np.ndarray]) -> tuple[np.ndarray, ...]:
        return tuple(np.clip(np.searchsorted(e, np.nan_to_num(v), side="right") - 1, 0, n - 1)
                     for e, v, n in zip(self.edges, predictors, self.nmad.shape))

    def factor(self, predictors: list[np.ndarray]) -> np.ndarray:
        """σ multiplier per cell, ≥ 1 (a cell with any NaN predictor: 1)."""
        f = np.maximum(1.0, self.nmad[self._index(predictors)] / self.reference_nmad)
        ok = np.logical_and.reduce([np.isfinite(v) for v in predictors])
        return np.where(ok, f, 1.0).astype(np.float32)

    def table(self, names: tuple[str, ...] = PREDICTORS) -> pd.DataFrame:
        """One row per bin: each predictor's range, cells, NMAD (m), factor."""
        rows = []
        for idx in np.ndindex(*self.nmad.shape):
            row: dict[str, Any] = {}
            for name, e, i in zip(names, self.edges, idx):
                row[f"{name}_min"], row[f"{name}_max"] = float(e[i]), float(e[i + 1])
            row.update(cells=int(self.count[idx]), nmad_m=float(self.nmad[idx]),
                       factor=float(max(1.0, self.nmad[idx] / self.reference_nmad)))
            rows.append(row)
        return pd.DataFrame(rows)


def _nmad(v: np.ndarray) -> float:
    return float(1.4826 * np.median(np.abs(v - np.median(v))))


def fit_error_model(dod: np.ndarray, predictors: list[np.ndarray], unchanged: np.ndarray,
                    bins: int = 10, min_cells: int = 100) -> ErrorModel | None:
    """Bin the DoD's NMAD by quantiles of each predictor over the ``unchanged`` cells.

    Parameters
    ----------
    dod : ndarray
        DEM₂ − DEM₁ after co-registration (NaN voids).
    predictors : list of ndarray
        Arrays of ``dod``'s shape (:func:`terrain_predictors`).
    unchanged : ndarray bool
        Cells assumed unchanged: outside every unstable mask, not voids (plants kept).
    bins : int
        Quantile bins per predictor ([I] 10; repeated edges are merged, so a predictor that
        is 0 on most cells, such as the height above the ground, gets fewer).
    min_cells : int
        A bin with fewer cells takes the NMAD of the nearest filled bin (in bin indices;
        [I] 100: the NMAD's relative standard error is about 1.1 / √n = 11 %).

    Returns
    -------
    ErrorModel or None
        None when fewer than ``min_cells`` cells per bin of a full grid of bins are
        unchanged, or their NMAD is 0.

    Notes
    -----
    O(n log n) for the quantiles and the sort over the n unchanged cells.
    """
    ok = unchanged & np.isfinite(dod)
    for v in predictors:
        ok &= np.isfinite(v)
    n = int(ok.sum())
    need = bins ** len(predictors) * min_cells
    if n < need:
        log.warning("error model: %d unchanged cells, fewer than %d: uniform sigma", n, need)
        return None
    d = dod[ok].astype(np.float64)
    ref = _nmad(d)
    if ref <= 0:
        return None
    q = np.linspace(0.0, 1.0, bins + 1)[1:-1]
    edges, index = [], []
    for v in predictors:
        x = v[ok].astype(np.float64)
        # quantile edges, repeated ones merged (a level plain has one slope): at most ``bins`` per predictor
        e = np.unique(np.concatenate([[-np.inf], np.quantile(x, q), [np.inf]]))
        edges.append(e)
        index.append(np.clip(np.searchsorted(e, x, side="right") - 1, 0, e.size - 2))
    shape = tuple(e.size - 1 for e in edges)
    flat = np.ravel_multi_index(tuple(index), shape)
    order = np.argsort(flat, kind="stable")
    counts = np.bincount(flat, minlength=int(np.prod(shape)))
    starts = np.concatenate([[0], np.cumsum(counts)])
    nm = np.full(counts.size, np.nan)
    for k in np.flatnonzero(counts >= min_cells):
        nm[k] = _nmad(d[order[starts[k]:starts[k + 1]]])
    nm = nm.reshape(shape)
    filled = np.isfinite(nm)
    if not filled.all():
        idx = ndimage.distance_transform_edt(~filled, return_distances=False, return_indices=True)
        nm = nm[tuple(idx)]
    log.info("error model: %d unchanged cells, NMAD %.3f m overall, %.3f-%.3f m per bin (%d of %d bins filled, shape %s)",
             n, ref, float(np.min(nm)), float(np.max(nm)), int(filled.sum()), filled.size, shape)
    return ErrorModel(edges, nm, counts.reshape(shape), ref)


def heteroscedastic_sigma(sigma: np.ndarray, z1: np.ndarray, dod: np.ndarray, unchanged: np.ndarray, cell: float,
                          window_m: float, object_window_m: float,
                          reference_cells: tuple[np.ndarray, np.ndarray] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
    """σ_DoD times the terrain factor of the error model fitted on ``unchanged`` cells.

    Parameters
    ----------
    sigma : ndarray (H, W)
        Propagated σ_DoD from the epochs' accuracies (m).
    z1 : ndarray (H, W)
        Epoch-1 DEM (the predictors' surface).
    dod : ndarray (H, W)
        Co-registered DEM₂ − DEM₁, NaN voids.
    unchanged : ndarray (H, W) bool
        Cells outside every unstable mask and not voids.
    cell : float
        Grid cell (m).
    window_m : float
        The DEM's horizontal resolution (m; the matching window), at which slope and
        curvature are read.
    object_window_m : float
        The object filter's window (m) of the height above the ground.
    reference_cells : (rows, cols) or None
        The checkpoints' cells: ``sigma`` states the DEMs' error there, so the factor is each
        bin's NMAD over the median NMAD of the checkpoints' bins (their terrain). None or no
        checkpoint on the grid: over the NMAD of all unchanged cells.

    Returns
    -------
    sigma : ndarray (H, W) float32
        σ_DoD × factor (unchanged when there are too few unchanged cells for a model).
    row : dict
        The factor's row for ``sigma.csv`` (``epoch`` "DoD factor", ``source`` with its
        median, 90th percentile and maximum over the DoD's cells).

    Notes
    -----
    O(n log n) over the n grid cells; three float32 predictor grids beside the inputs.
    """
    preds = terrain_predictors(z1, cell, window_m, object_window_m)
    model = fit_error_model(dod, preds, unchanged)
    if model is None:
        return sigma, {"epoch": "DoD factor", "source": "heteroscedastic: too few unchanged cells, uniform", "sigma_m": np.nan}
    if reference_cells is not None:
        r, c = reference_cells
        inside = (r >= 0) & (r < z1.shape[0]) & (c >= 0) & (c < z1.shape[1])
        r, c = r[inside], c[inside]
        at = [v[r, c] for v in preds]
        ok_at = np.logical_and.reduce([np.isfinite(v) for v in at]) if r.size else np.zeros(0, bool)
        if ok_at.any():
            ref = float(np.median(model.nmad[model._index([v[ok_at] for v in at])]))
            log.info("error model: the %d checkpoints' bins have a median NMAD of %.3f m (all unchanged cells %.3f m)",
                     int(ok_at.sum()), ref, model.reference_nmad)
            model.reference_nmad = ref
    f = model.factor(preds)
    del preds
    ok = np.isfinite(dod)
    med, p90, top = (float(v) for v in np.percentile(f[ok], [50, 90, 100])) if ok.any() else (1.0, 1.0, 1.0)
    log.info("heteroscedastic sigma: factor median %.2f, p90 %.2f, max %.2f (DoD NMAD on unchanged ground %.3f m)",
             med, p90, top, model.reference_nmad)
    return (sigma * f).astype(np.float32), {
        "epoch": "DoD factor", "sigma_m": np.nan,
        "source": f"heteroscedastic: x NMAD(slope, curvature, height-above-ground bin) / {model.reference_nmad:.3f} m, "
                  f"at least 1; median {med:.2f}, p90 {p90:.2f}, max {top:.2f}"}
