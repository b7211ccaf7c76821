"""Heteroscedastic DoD error: how the spread of elevation differences grows with the terrain.

A DSM from dense matching is least precise where the surface is steep or sharply curved:
gully walls and rims, shrub and tree crowns, buildings (the matching window smooths them and
the two epochs' views see them differently). The checkpoints that give each epoch's σ sit on
open, nearly level ground, so a uniform σ from them under-states the DoD's noise there, and
thresholds at 1.96 σ flag such unchanged cells as change. After Hugonnet et al. (2022; xDEM's
``infer_heteroscedasticity_from_stable``) the DoD's spread is binned by slope and curvature on
ground that has not changed (outside every unstable mask; plants included, they are part of the
noise), and each cell's σ_DoD is the propagated checkpoint σ times the ratio of its bin's NMAD to
the NMAD of all those cells (at least 1: the checkpoints' σ is the floor, never lowered).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd
from scipy import ndimage

log = logging.getLogger(__name__)


def terrain_predictors(z: np.ndarray, cell: float, window_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Slope (degrees) and |Laplacian curvature| (1/m) of ``z`` box-smoothed over ``window_m``.

    The box is the DEM's horizontal resolution (the matching window): finer relief is noise.
    NaN cells take the grid mean for the filters and stay NaN. O(cells).
    """
    ok = np.isfinite(z)
    zf = np.where(ok, z, np.nanmean(z) if ok.any() else 0.0).astype(np.float64)
    k = max(1, int(round(window_m / cell)))
    if k > 1:
        zf = ndimage.uniform_filter(zf, k, mode="nearest")
    gy, gx = np.gradient(zf, cell)
    slope = np.degrees(np.arctan(np.hypot(gx, gy)))
    curv = np.abs(ndimage.laplace(zf, mode="nearest")) / (cell * cell)
    slope[~ok], curv[~ok] = np.nan, np.nan
    return slope.astype(np.float32), curv.astype(np.float32)


@dataclass
class ErrorModel:
    """NMAD of the DoD per (slope, curvature) bin on unchanged ground and the factor it gives each cell."""

    slope_edges: np.ndarray
    curvature_edges: np.ndarray
    nmad: np.ndarray  # (slope bins, curvature bins), empty bins filled
    count: np.ndarray
    reference_nmad: float

    def factor(self, slope: np.ndarray, curvature: np.ndarray) -> np.ndarray:
        """σ multiplier per cell, ≥ 1 (NaN predictors: 1)."""
        i = np.clip(np.searchsorted(self.slope_edges, np.nan_to_num(slope), side="right") - 1, 0, self.nmad.shape[0] - 1)
        j = np.clip(np.searchsorted(self.curvature_edges, np.nan_to_num(curvature), side="right") - 1, 0, self.nmad.shape[1] - 1)
        f = np.maximum(1.0, self.nmad[i, j] / self.reference_nmad)
        return np.where(np.isfinite(slope) & np.isfinite(curvature), f, 1.0).astype(np.float32)

    def table(self) -> pd.DataFrame:
        """One row per bin: slope and curvature ranges, cells, NMAD (m), factor."""
        rows = []
        for i in range(self.nmad.shape[0]):
            for j in range(self.nmad.shape[1]):
                rows.append(dict(slope_min_deg=self.slope_edges[i], slope_max_deg=self.slope_edges[i + 1],
                                 curvature_min=self.curvature_edges[j], curvature_max=self.curvature_edges[j + 1],
                                 cells=int(self.count[i, j]), nmad_m=float(self.nmad[i, j]),
                                 factor=float(max(1.0, self.nmad[i, j] / self.reference_nmad))))
        return pd.DataFrame(rows)


def _nmad(v: np.ndarray) -> float:
    return float(1.4826 * np.median(np.abs(v - np.median(v))))


def fit_error_model(dod: np.ndarray, slope: np.ndarray, curvature: np.ndarray, unchanged: np.ndarray,
                    bins: int = 10, min_cells: int = 100) -> ErrorModel | None:
    """Bin the DoD's NMAD by slope and curvature quantiles over the ``unchanged`` cells.

    Parameters
    ----------
    dod : ndarray (H, W)
        DEM₂ − DEM₁ after co-registration (NaN voids).
    slope, curvature : ndarray (H, W)
        :func:`terrain_predictors` of DEM₁.
    unchanged : ndarray (H, W) bool
        Cells assumed unchanged: outside every unstable mask, not voids (plants kept).
    bins : int
        Quantile bins per predictor ([I] 10: 100 bins, each ≥ ``min_cells``).
    min_cells : int
        A bin with fewer cells takes the NMAD of the nearest filled bin (in bin indices;
        [I] 100: the NMAD's relative standard error is about 1.1 / √n = 11 %).

    Returns
    -------
    ErrorModel or None
        None when fewer than ``bins² · min_cells`` cells are unchanged or their NMAD is 0.

    Notes
    -----
    O(n log n) for the quantiles and one sort per bin over the n unchanged cells.
    """
    ok = unchanged & np.isfinite(dod) & np.isfinite(slope) & np.isfinite(curvature)
    n = int(ok.sum())
    if n < bins * bins * min_cells:
        log.warning("error model: %d unchanged cells, fewer than %d: uniform sigma", n, bins * bins * min_cells)
        return None
    d, s, c = dod[ok].astype(np.float64), slope[ok].astype(np.float64), curvature[ok].astype(np.float64)
    ref = _nmad(d)
    if ref <= 0:
        return None
    q = np.linspace(0.0, 1.0, bins + 1)
    # quantile edges, repeated ones merged (a level plain has one slope): at most ``bins`` per predictor
    se, ce = (np.unique(np.concatenate([[-np.inf], np.quantile(v, q)[1:-1], [np.inf]])) for v in (s, c))
    ns, nc = se.size - 1, ce.size - 1
    i = np.clip(np.searchsorted(se, s, side="right") - 1, 0, ns - 1)
    j = np.clip(np.searchsorted(ce, c, side="right") - 1, 0, nc - 1)
    flat = i * nc + j
    order = np.argsort(flat, kind="stable")
    counts = np.bincount(flat, minlength=ns * nc)
    starts = np.concatenate([[0], np.cumsum(counts)])
    nm = np.full(ns * nc, np.nan)
    for k in range(ns * nc):
        if counts[k] >= min_cells:
            nm[k] = _nmad(d[order[starts[k]:starts[k + 1]]])
    nm = nm.reshape(ns, nc)
    filled = np.isfinite(nm)
    if not filled.all():
        idx = ndimage.distance_transform_edt(~filled, return_distances=False, return_indices=True)
        nm = nm[tuple(idx)]
    log.info("error model: %d unchanged cells, NMAD %.3f m overall, %.3f-%.3f m per bin (%d of %d bins filled)",
             n, ref, float(np.nanmin(nm)), float(np.nanmax(nm)), int(filled.sum()), ns * nc)
    return ErrorModel(se, ce, nm, counts.reshape(ns, nc), ref)


def heteroscedastic_sigma(sigma: np.ndarray, z1: np.ndarray, dod: np.ndarray, unchanged: np.ndarray, cell: float,
                          window_m: float) -> tuple[np.ndarray, dict[str, Any]]:
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

    Returns
    -------
    sigma : ndarray (H, W) float32
        σ_DoD × factor (unchanged when there are too few unchanged cells for a model).
    row : dict
        The factor's row for ``sigma.csv`` (``epoch`` "DoD factor", ``source`` with its
        median, 90th percentile and maximum over the DoD's cells).

    Notes
    -----
    O(n log n) over the n grid cells; two float32 predictor grids beside the inputs.
    """
    slope, curv = terrain_predictors(z1, cell, window_m)
    model = fit_error_model(dod, slope, curv, unchanged)
    if model is None:
        return sigma, {"epoch": "DoD factor", "source": "heteroscedastic: too few unchanged cells, uniform", "sigma_m": np.nan}
    f = model.factor(slope, curv)
    del slope, curv
    ok = np.isfinite(dod)
    med, p90, top = (float(v) for v in np.percentile(f[ok], [50, 90, 100])) if ok.any() else (1.0, 1.0, 1.0)
    log.info("heteroscedastic sigma: factor median %.2f, p90 %.2f, max %.2f (DoD NMAD on unchanged ground %.3f m)",
             med, p90, top, model.reference_nmad)
    return (sigma * f).astype(np.float32), {
        "epoch": "DoD factor", "sigma_m": np.nan,
        "source": f"heteroscedastic: x NMAD(slope, curvature bin) / {model.reference_nmad:.3f} m, at least 1; "
                  f"median {med:.2f}, p90 {p90:.2f}, max {top:.2f}"}
