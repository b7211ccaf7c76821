"""Relief shading of a DSM: hillshade and positive openness (a sky-view-like measure)."""

from __future__ import annotations

import numpy as np

from kitegully.dense.kernels import openness_kernel


def hillshade(z: np.ndarray, cell: float, azimuth_deg: float = 315.0, altitude_deg: float = 45.0) -> np.ndarray:
    """Lambertian hillshade in 0–1 for a sun at ``azimuth_deg`` (from north, clockwise) and
    ``altitude_deg``; rows go south, columns east. NaN where the DSM is NaN. O(cells).

    Parameters
    ----------
    z : ndarray (H, W)
        Elevations (m, NaN = no value).
    cell : float
        Cell size (m).
    azimuth_deg : float
        Sun azimuth (degrees from north, clockwise).
    altitude_deg : float
        Sun elevation above the horizon (degrees).

    Returns
    -------
    ndarray (H, W) float64
        Illumination in 0–1.
    """
    gy, gx = np.gradient(np.asarray(z, float), cell)
    dzdx, dzdy = gx, -gy  # rows go south: d/dy(north) = -d/drow
    az, alt = np.radians(azimuth_deg), np.radians(altitude_deg)
    sx, sy, sz = np.sin(az) * np.cos(alt), np.cos(az) * np.cos(alt), np.sin(alt)
    nrm = np.sqrt(dzdx ** 2 + dzdy ** 2 + 1.0)
    shade = (-dzdx * sx - dzdy * sy + sz) / nrm
    return np.clip(shade, 0.0, 1.0)


def openness(z: np.ndarray, cell: float, radius_m: float) -> np.ndarray:
    """Positive openness (degrees, 90 on a plane, less in hollows and gullies) over 8
    directions within ``radius_m`` (Yokoyama et al. 2002). O(cells · 8 · radius/cell).

    Parameters
    ----------
    z : ndarray (H, W)
        Elevations (m, NaN = no value).
    cell : float
        Cell size (m).
    radius_m : float
        Search radius (m); at least one cell.

    Returns
    -------
    ndarray (H, W) float64
        Openness (degrees); NaN where ``z`` is NaN or no direction has a valid cell.
    """
    out = np.empty(z.shape, np.float64)
    openness_kernel(np.ascontiguousarray(z, dtype=np.float64), float(cell), max(1, int(round(radius_m / cell))), out)
    return out
