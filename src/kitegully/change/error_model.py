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
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd
from scipy import ndimage

from kitegully.change.coregister import height_above_ground
from kitegully.evaluate.dem import nmad

log = logging.getLogger(__name__)

#: Predictor names, in the order of :func:`terrain_predictors`.
PREDICTORS = ("slope_deg", "curvature_per_m", "height_above_ground_m")
#: [I] Quantile bins per predictor and the fewest cells whose NMAD a bin keeps (~11 % standard error).
BINS, MIN_CELLS = 10, 100
#: [I] The model is fitted on the unchanged cells of a regular lattice of at most this many cells
#: (every k-th row and column): 2 000 per bin of 10³, and the same cells whether the grid is one job or tiles.
MAX_SAMPLES = 2_000_000
#: Appended to the σ_DoD raster's definition tag when the factor is applied.
SIGMA_FACTOR_TAG = " x heteroscedastic factor (slope, curvature, height above ground)"


def terrain_predictors(z: np.ndarray, cell: float, window_m: float, object_window_m: float,
                       fill: float | None = None) -> list[np.ndarray]:
    """Slope (degrees), |Laplacian curvature| (1/m) and height above the ground (m) of ``z``.

    Slope and curvature are read on ``z`` box-smoothed over ``window_m`` (the DEM's horizontal
    resolution, the matching window: finer relief is noise); the height above the ground is
    :func:`kitegully.change.coregister.height_above_ground` over ``object_window_m`` (the
    change stage's object filter window). NaN cells take ``fill`` (default the highest
    elevation) for the filters and stay NaN. O(cells · object window).

    Parameters
    ----------
    z : ndarray (H, W)
        Elevations (m); NaN is nodata.
    cell : float
        Cell size (m).
    window_m : float
        Smoothing window (m) of slope and curvature.
    object_window_m : float
        Window (m) of the height above the ground.
    fill : float or None
        Elevation (m) given to NaN cells for the filters; None takes the highest elevation of ``z``.

    Returns
    -------
    slope_deg, curvature_per_m, height_above_ground_m : ndarray (H, W) float32
        The predictors in the order of :data:`PREDICTORS`, as a list; NaN where ``z`` is NaN.
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

    def to_json(self) -> dict[str, Any]:
        """Plain lists (±inf edges as JSON's Infinity) for the tile jobs."""
        return {"edges": [e.tolist() for e in self.edges], "nmad": self.nmad.tolist(), "count": self.count.tolist(),
                "reference_nmad": self.reference_nmad}

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> "ErrorModel":
        """Rebuild a model from the dict :meth:`to_json` made."""
        return cls([np.asarray(e, np.float64) for e in d["edges"]], np.asarray(d["nmad"], np.float64),
                   np.asarray(d["count"], np.int64), float(d["reference_nmad"]))

    def refer_to(self, predictors_at_checkpoints: list[np.ndarray]) -> None:
        """Make the median NMAD of the checkpoints' bins the reference (σ was measured on their terrain)."""
        ok = np.logical_and.reduce([np.isfinite(v) for v in predictors_at_checkpoints])
        if ok.any():
            ref = float(np.median(self.nmad[self._index([v[ok] for v in predictors_at_checkpoints])]))
            log.info("error model: the %d checkpoints' bins have a median NMAD of %.3f m (all unchanged cells %.3f m)",
                     int(ok.sum()), ref, self.reference_nmad)
            self.reference_nmad = ref

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


def lattice_step(n_cells: int, max_samples: int | None = None) -> int:
    """Row and column step of the sampling lattice: at most ``max_samples`` (default :data:`MAX_SAMPLES`) of ``n_cells``."""
    return max(1, math.ceil(math.sqrt(n_cells / (MAX_SAMPLES if max_samples is None else max_samples))))


def predictor_halo(cell: float, window_m: float, object_window_m: float) -> int:
    """Cells beyond a window that :func:`terrain_predictors` reads for the window's cells.

    Parameters
    ----------
    cell : float
        Cell size (m).
    window_m, object_window_m : float
        The smoothing and object windows (m) passed to :func:`terrain_predictors`.

    Returns
    -------
    int
        Halo width (cells).
    """
    k = max(1, int(round(window_m / cell)))
    ko = max(3, int(round(object_window_m / cell)) | 1)
    return max(k // 2 + 2, max(3, (ko // 3) | 1) // 2 + 2 * (ko // 2)) + 1


def checkpoint_cells(epochs: Any, grid: Any) -> tuple[np.ndarray, np.ndarray] | None:
    """Grid (row, col) of the checkpoints of every epoch whose accuracy is given by checkpoints; None if none is."""
    rows, cols = [], []
    for e in epochs:
        path = e.accuracy.get("checkpoints")
        if path:
            cp = pd.read_csv(path)
            r, c = grid.rowcol(cp["x"].to_numpy(float), cp["y"].to_numpy(float))
            rows.append(np.round(np.asarray(r)).astype(np.int64))
            cols.append(np.round(np.asarray(c)).astype(np.int64))
    if not rows:
        return None
    r, c = np.concatenate(rows), np.concatenate(cols)
    inside = (r >= 0) & (r < grid.height) & (c >= 0) & (c < grid.width)
    return r[inside], c[inside]


def factor_row(model: ErrorModel | None, factor: np.ndarray | None = None, dod: np.ndarray | None = None) -> dict[str, Any]:
    """The factor's row for ``sigma.csv``: its median, 90th percentile and maximum over the DoD's cells (no model: uniform).

    Parameters
    ----------
    model : ErrorModel or None
        The fitted model; None gives the uniform row.
    factor : ndarray (H, W) or None
        σ multiplier per cell (:meth:`ErrorModel.factor`); None gives the uniform row.
    dod : ndarray (H, W) or None
        The DoD; its finite cells are summarised. None gives the uniform row.

    Returns
    -------
    dict
        ``epoch``, ``source`` (the text of the row) and ``sigma_m`` (NaN).
    """
    if model is None or factor is None or dod is None:

        return {"epoch": "DoD factor", "source": "heteroscedastic: too few unchanged cells, uniform", "sigma_m": np.nan}
    ok = np.isfinite(dod)
    med, p90, top = (float(v) for v in np.percentile(factor[ok], [50, 90, 100])) if ok.any() else (1.0, 1.0, 1.0)
    log.info("heteroscedastic sigma: factor median %.2f, p90 %.2f, max %.2f (reference NMAD %.3f m)",
             med, p90, top, model.reference_nmad)
    return {"epoch": "DoD factor", "sigma_m": np.nan,
            "source": f"heteroscedastic: x NMAD(slope, curvature, height-above-ground bin) / {model.reference_nmad:.3f} m, "
                      f"at least 1; median {med:.2f}, p90 {p90:.2f}, max {top:.2f}"}


def fit_error_model(dod: np.ndarray, predictors: list[np.ndarray], unchanged: np.ndarray,
                    bins: int | None = None, min_cells: int | None = None) -> ErrorModel | None:
    """Bin the DoD's NMAD by quantiles of each predictor over the ``unchanged`` cells.

    Parameters
    ----------
    dod : ndarray
        DEM₂ − DEM₁ after co-registration (NaN voids).
    predictors : list of ndarray
        Arrays of ``dod``'s shape (:func:`terrain_predictors`).
    unchanged : ndarray bool
        Cells assumed unchanged: outside every unstable mask, not voids (plants kept).
    bins : int, optional
        Quantile bins per predictor (default :data:`BINS`; repeated edges are merged, so a
        predictor that is 0 on most cells, such as the height above the ground, gets fewer).
    min_cells : int, optional
        A bin with fewer cells takes the NMAD of the nearest filled bin (in bin indices;
        default :data:`MIN_CELLS`).

    Returns
    -------
    ErrorModel or None
        None when fewer than ``min_cells`` cells per bin of a full grid of bins are
        unchanged, or their NMAD is 0.

    Notes
    -----
    O(n log n) for the quantiles and the sort over the n unchanged cells.
    """
    bins = BINS if bins is None else bins
    min_cells = MIN_CELLS if min_cells is None else min_cells
    ok = unchanged & np.isfinite(dod)
    for v in predictors:
        ok &= np.isfinite(v)
    n = int(ok.sum())
    need = bins ** len(predictors) * min_cells
    if n < need:
        log.warning("error model: %d unchanged cells, fewer than %d: uniform sigma", n, need)
        return None
    d = dod[ok].astype(np.float64)
    ref = nmad(d)
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
        nm[k] = nmad(d[order[starts[k]:starts[k + 1]]])
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
    """σ_DoD times the terrain factor of the error model fitted on the unchanged lattice cells.

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
        The factor's row for ``sigma.csv`` (:func:`factor_row`).

    Notes
    -----
    The model is fitted on the cells of every :func:`lattice_step`-th row and column, the
    same cells as the tile jobs (:mod:`kitegully.change.tiles`) gather. O(n log n) over the
    n grid cells; three float32 predictor grids beside the inputs.
    """
    preds = terrain_predictors(z1, cell, window_m, object_window_m)
    k = lattice_step(z1.size)
    lattice = np.zeros(z1.shape, bool)
    lattice[::k, ::k] = True
    model = fit_error_model(dod, preds, unchanged & lattice)
    if model is None:
        return sigma, factor_row(None)
    if reference_cells is not None and reference_cells[0].size:
        model.refer_to([v[reference_cells] for v in preds])
    f = model.factor(preds)
    del preds
    return (sigma * f).astype(np.float32), factor_row(model, f, dod)
