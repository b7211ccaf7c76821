"""Relief shading of a DEM for figures: the Lambertian hillshade every map of the project is drawn over."""

from __future__ import annotations

import numpy as np


def hillshade(z: np.ndarray, cell: float, azimuth_deg: float = 315.0, altitude_deg: float = 45.0) -> np.ndarray:
    """Lambertian hillshade in 0–1 for a sun at ``azimuth_deg`` (from north, clockwise) and
    ``altitude_deg``; rows go south, columns east. NaN where the DSM is NaN, and only there:
    the gradient next to a void is taken with the void at the DSM's mean height. O(cells).
    The one hillshade of the project's figures (DSM, gully, polygon and validation maps).

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
    z = np.array(z, dtype=float)  # a float64 copy, its voids filled in place
    valid = np.isfinite(z)
    if not valid.all():
        z[~valid] = np.mean(z[valid]) if valid.any() else 0.0
    gy, gx = np.gradient(z, cell)
    dzdx, dzdy = gx, -gy  # rows go south: d/dy(north) = -d/drow
    az, alt = np.radians(azimuth_deg), np.radians(altitude_deg)
    sx, sy, sz = np.sin(az) * np.cos(alt), np.cos(az) * np.cos(alt), np.sin(alt)
    nrm = np.sqrt(dzdx ** 2 + dzdy ** 2 + 1.0)
    shade = (-dzdx * sx - dzdy * sy + sz) / nrm
    return np.where(valid, np.clip(shade, 0.0, 1.0), np.nan)
