"""NDVI, slope and aspect rasters (paper 004 Eqs 1–3, with the METHODS 5.3 [I] conventions).

Slope is the angle between the surface's unit normal and the vertical, ``acos(|n_z|)``
(Eq. 1 written for a normal of either orientation). Aspect is the azimuth of the
*downslope* direction, clockwise from grid north, ``atan2(u_E, u_N) mod 360°`` with the
upward normal ``u`` (Eq. 2 applied to a downward normal gives the upslope direction with
a quadrant ambiguity; see METHODS 5.3). Flat cells have no aspect (NaN).
"""

from __future__ import annotations

import numpy as np

from kitegully import InputError
from kitegully.obia.indices import ndvi

__all__ = ["ndvi", "surface_normals", "slope_aspect"]


def surface_normals(dem: np.ndarray, cell: float) -> np.ndarray:
    """Upward unit normals (3, rows, cols) as (east, north, up) of a north-up DEM.

    Gradients by central differences (one-sided at the grid edges); nodata cells and
    cells next to nodata in a differencing direction are NaN. O(cells).
    """
    z = np.asarray(dem, dtype=np.float64)
    if z.ndim != 2 or min(z.shape) < 2:
        raise InputError(f"slope/aspect: the DEM must be a 2-D grid of at least 2 × 2 cells, got shape {z.shape}")
    if not cell > 0:
        raise InputError(f"slope/aspect: cell size must be positive, got {cell}")
    dz_drow, dz_dcol = np.gradient(z, cell)
    dz_dx = dz_dcol          # columns go east
    dz_dy = -dz_drow         # rows go south, so northing decreases with the row
    u = np.stack([-dz_dx, -dz_dy, np.ones_like(z)])
    u[:, ~np.isfinite(z)] = np.nan
    return u / np.sqrt((u * u).sum(axis=0))


def slope_aspect(dem: np.ndarray, cell: float, flat_tolerance_deg: float = 0.01) -> tuple[np.ndarray, np.ndarray]:
    """Slope and aspect (degrees, float32) of a north-up DEM.

    Parameters
    ----------
    dem : (rows, cols) array
        Elevations (m), NaN for nodata.
    cell : float
        Cell size (m).
    flat_tolerance_deg : float
        Slopes below this have no defined aspect (NaN).

    Returns
    -------
    slope_deg : array
        ``acos(|n_z|)`` in degrees, 0 = horizontal.
    aspect_deg : array
        Downslope azimuth clockwise from north, [0, 360); NaN on flats and nodata.
    """
    u = surface_normals(dem, cell)
    slope = np.degrees(np.arccos(np.clip(np.abs(u[2]), 0.0, 1.0)))
    aspect = np.degrees(np.arctan2(u[0], u[1])) % 360.0
    aspect[~(slope >= flat_tolerance_deg)] = np.nan
    return slope.astype(np.float32), aspect.astype(np.float32)
