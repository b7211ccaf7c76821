"""Positive openness of a DSM (a sky-view-like relief measure); its hillshade is :func:`kitegully.terrain.shading.hillshade`."""

from __future__ import annotations

import numpy as np

from kitegully.dense.kernels import openness_kernel


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
