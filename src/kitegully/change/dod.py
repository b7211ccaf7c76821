"""Epoch DEMs in, DEM of difference out: input checks, the common grid, DoD = DEM₂ − DEM₁.

A site gives each epoch as a DEM GeoTIFF (a twin's dense DSM, LiDAR, TLS, another
software's DSM) with its stated vertical accuracy. Everything a user can get wrong here
(missing file, different CRS, extents that do not overlap, a nodata sentinel the file does
not declare, no accuracy) stops with one :class:`kitegully.InputError` sentence.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import rasterio
from scipy import ndimage

from kitegully import InputError
from kitegully.io.raster import GridSpec, Raster

log = logging.getLogger(__name__)

#: Values that are nodata sentinels in practice (ESRI, GDAL, LAStools, Surfer, float min).
SENTINEL_ABS = 9990.0
ACCURACY_KEYS = ("sd_m", "rmse_m", "error_raster", "checkpoints")


@dataclass
class Epoch:
    """One survey: its DEM on the common grid and how its accuracy is stated."""

    name: str
    dem: Raster
    accuracy: dict[str, Any]
    path: str
    correlation: Raster | None = None


def _check_nodata(path: Path, data: np.ndarray, declared: float | None, key: str) -> np.ndarray:
    """Apply a declared nodata value; refuse sentinel-looking values nobody declared."""
    with rasterio.open(path) as src:
        file_nodata = src.nodata
    if declared is not None:
        data = np.where(data == declared, np.nan, data)
    elif file_nodata is None:
        bad = np.isfinite(data) & (np.abs(data) >= SENTINEL_ABS)
        if bad.any():
            v = float(data[bad][0])
            raise InputError(
                f"{path}: declares no nodata value but {int(bad.sum())} cells hold {v:g}, a nodata sentinel, "
                f"not an elevation; declare it in the file or as {key}.nodata"
            )
    return data.astype(np.float32, copy=False)


def load_epoch(spec: Mapping[str, Any], key: str, site_crs: str | None = None) -> Epoch:
    """Read one epoch's DEM and check its declared accuracy.

    Parameters
    ----------
    spec
        ``{name, dem, nodata, accuracy: {sd_m | rmse_m | error_raster | checkpoints}}``.
    key
        Config path used in messages, e.g. ``change.epochs[1]``.
    site_crs
        The site's CRS; the DEM must be in it.

    Returns
    -------
    Epoch
    """
    path = Path(spec["dem"])
    if not path.exists():
        raise InputError(f"{path}: DEM file of {key} not found")
    acc = {k: v for k, v in (spec.get("accuracy") or {}).items() if v is not None}
    given = [k for k in ACCURACY_KEYS if k in acc]
    if not given:
        raise InputError(f"{key} ({path}): no vertical accuracy stated; give one of {', '.join(ACCURACY_KEYS)}")
    if len(given) > 1:
        raise InputError(f"{key} ({path}): state the vertical accuracy once, got {', '.join(given)}")
    for k in ("sd_m", "rmse_m"):
        if k in acc and not float(acc[k]) > 0:
            raise InputError(f"{key}.accuracy.{k}: must be > 0 m, got {acc[k]}")
    r = Raster.read(path)
    if r.data.dtype.kind != "f":
        r = Raster(r.data.astype(np.float32), r.grid, None) if r.nodata is None else Raster(
            np.where(r.data == r.nodata, np.nan, r.data).astype(np.float32), r.grid)
    data = _check_nodata(path, r.data, spec.get("nodata"), key)
    if site_crs is not None and not rasterio.crs.CRS.from_user_input(r.crs) == rasterio.crs.CRS.from_user_input(site_crs):
        raise InputError(f"{path}: CRS {r.crs} differs from the site CRS {site_crs}; reproject the DEM first")
    if not np.isfinite(data).any():
        raise InputError(f"{path}: DEM holds no valid elevation")
    corr = None
    if spec.get("correlation"):
        cpath = Path(spec["correlation"])
        if not cpath.exists():
            raise InputError(f"{cpath}: correlation raster of {key} not found")
        corr = Raster.read(cpath)
        if not rasterio.crs.CRS.from_user_input(corr.crs) == rasterio.crs.CRS.from_user_input(r.crs):
            raise InputError(f"{cpath}: CRS {corr.crs} of the correlation raster differs from its DEM's {r.crs}")
    return Epoch(str(spec.get("name", key)), Raster(data, r.grid), acc, str(path), corr)


def matching_voids(epochs: tuple[Epoch, ...], grid: GridSpec, min_correlation: float | None,
                   margin_m: float = 0.0, valid: np.ndarray | None = None) -> np.ndarray:
    """Cells of ``grid`` where an epoch's dense-matching correlation is below ``min_correlation``.

    Those are not measurements (see :class:`~kitegully.change.params.ChangeParams`); an epoch
    without a correlation raster, or ``min_correlation`` None, adds no void (and with no
    correlation raster at all there is no margin either: DEMs not from image matching). Correlation is
    sampled at the nearest cell (an NCC is not interpolated across a void edge). The voids
    and the edges of ``valid`` (cells where both DEMs hold an elevation) then grow by
    ``margin_m`` (Euclidean distance between cell centres). O(cells).

    Parameters
    ----------
    epochs : tuple of Epoch
        The epochs; each one's ``correlation`` raster, if any, is read.
    grid : GridSpec
        The common grid.
    min_correlation : float or None
        Lowest correlation that counts as matched; None adds no void.
    margin_m : float
        Distance (m) by which the voids and the edges of ``valid`` grow; 0 adds none.
    valid : ndarray (H, W) bool or None
        Cells where both DEMs hold an elevation; None grows the voids only.

    Returns
    -------
    ndarray (H, W) bool
        The voids and their margin.
    """
    out = np.zeros((grid.height, grid.width), bool)
    if min_correlation is None or all(e.correlation is None for e in epochs):
        return out
    for e in epochs:
        if e.correlation is None:
            continue
        xs, ys = grid.cell_centres()
        rows, _ = e.correlation.grid.rowcol(np.zeros(1), ys)
        _, cols = e.correlation.grid.rowcol(xs, np.zeros(1))
        ri, ci = np.rint(rows).astype(int), np.rint(cols).astype(int)
        h, w = e.correlation.data.shape
        inside = ((ri >= 0) & (ri < h))[:, None] & ((ci >= 0) & (ci < w))[None, :]
        c = e.correlation.data[np.clip(ri, 0, h - 1)[:, None], np.clip(ci, 0, w - 1)[None, :]]
        low = inside & ~(c >= min_correlation)  # NaN correlation (unmatched) counts as low
        log.info("%s: %.2f %% of the common grid matched below NCC %.2f (voids)", e.name, 100.0 * low.mean(), min_correlation)
        out |= low
    if margin_m > 0:
        holes = out | (~valid if valid is not None else False)
        if holes.any():
            out |= ndimage.distance_transform_edt(~holes) * grid.cell <= margin_m + 1e-6
    return out


def overlap_grid(a: GridSpec, b: GridSpec, a_path: str = "epoch 1", b_path: str = "epoch 2") -> GridSpec:
    """Grid of ``a`` clipped to the overlap with ``b`` (whole cells of ``a``).

    Parameters
    ----------
    a, b : GridSpec
        Grids of the two DEMs.
    a_path, b_path : str
        Names of the two DEMs in messages.

    Returns
    -------
    GridSpec
        A window of ``a``.
    """
    if rasterio.crs.CRS.from_user_input(a.crs) != rasterio.crs.CRS.from_user_input(b.crs):
        raise InputError(f"{b_path}: CRS {b.crs} differs from {a_path}'s {a.crs}; reproject one DEM onto the other's CRS")
    ax0, ay0, ax1, ay1 = a.bounds
    bx0, by0, bx1, by1 = b.bounds
    x0, x1, y0, y1 = max(ax0, bx0), min(ax1, bx1), max(ay0, by0), min(ay1, by1)
    if x1 - x0 < 2 * a.cell or y1 - y0 < 2 * a.cell:
        raise InputError(f"{b_path}: extent {tuple(round(v, 1) for v in b.bounds)} does not overlap {a_path} "
                         f"{tuple(round(v, 1) for v in a.bounds)}")
    c0 = int(np.ceil((x0 - ax0) / a.cell - 1e-6))
    c1 = int(np.floor((x1 - ax0) / a.cell + 1e-6))
    r0 = int(np.ceil((a.y0 - y1) / a.cell - 1e-6))
    r1 = int(np.floor((a.y0 - y0) / a.cell + 1e-6))
    return a.window(r0, c0, r1 - r0, c1 - c0)


def resample(r: Raster, grid: GridSpec, dx: float = 0.0, dy: float = 0.0) -> np.ndarray:
    """Bilinear samples of ``r`` at the cell centres of ``grid`` shifted by (dx, dy) m.

    NaN propagates to every sample whose 2 × 2 neighbourhood touches nodata. O(cells).

    Parameters
    ----------
    r : Raster
        Source raster; NaN is nodata.
    grid : GridSpec
        Grid whose cell centres are sampled.
    dx, dy : float
        Shift east and north (m).

    Returns
    -------
    ndarray (H, W) float32
        Samples on ``grid``; NaN outside ``r``.
    """

    if grid == r.grid and dx == 0.0 and dy == 0.0:
        return r.data.astype(np.float32, copy=True)
    xs, ys = grid.cell_centres()
    rows, _ = r.grid.rowcol(np.zeros(1), ys + dy)
    _, cols = r.grid.rowcol(xs + dx, np.zeros(1))
    out = np.empty((grid.height, grid.width), np.float32)
    step = max(1, 4_000_000 // max(grid.width, 1))
    for i in range(0, grid.height, step):
        rr, cc = np.meshgrid(rows[i:i + step], cols, indexing="ij")
        out[i:i + step] = ndimage.map_coordinates(r.data.astype(np.float32, copy=False), [rr, cc], order=1,
                                                  mode="constant", cval=np.nan, prefilter=False)
    return out


def on_common_grid(e1: Epoch, e2: Epoch) -> tuple[GridSpec, np.ndarray, np.ndarray]:
    """Both DEMs on epoch 1's grid clipped to the overlap (epoch 2 resampled bilinearly)."""
    grid = overlap_grid(e1.dem.grid, e2.dem.grid, e1.path, e2.path)
    z1 = resample(e1.dem, grid)
    z2 = resample(e2.dem, grid)
    if not (np.isfinite(z1) & np.isfinite(z2)).any():
        raise InputError(f"{e2.path}: no cell holds an elevation in both epochs ({e1.path})")
    log.info("common grid %d x %d cells of %.3g m", grid.width, grid.height, grid.cell)
    return grid, z1, z2


def dem_of_difference(z1: np.ndarray, z2: np.ndarray) -> np.ndarray:
    """DoD = DEM₂ − DEM₁ (m; negative = lowering/erosion), NaN where either is nodata."""
    return (z2.astype(np.float64) - z1).astype(np.float32)
