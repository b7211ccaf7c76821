"""Slope from a DEM by a least-squares quadratic surface (Wood 1996).

In an n x n window (n odd) fit ``z = a x^2 + b y^2 + c x y + d x + e y + f``; the slope
at the centre is ``atan(sqrt(d^2 + e^2))``.  The least-squares coefficients ``d`` and
``e`` are fixed linear combinations of the window values, so they are two correlation
kernels: the whole slope map costs two n x n correlations, O(N n^2).
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from kitegully.terrain.holes import fill_nearest


def quadratic_kernels(window: int, cell: float) -> tuple[np.ndarray, np.ndarray]:
    """Correlation kernels giving the x and y gradient (d, e) of the LS quadratic fit.

    x grows east (columns), y grows north (rows go south), both in metres.
    """
    if window < 3 or window % 2 == 0:
        raise ValueError(f"slope window must be odd and >= 3, got {window}")
    h = window // 2
    rows, cols = np.mgrid[-h : h + 1, -h : h + 1]
    x = cols.ravel() * cell
    y = -rows.ravel() * cell
    design = np.column_stack([x * x, y * y, x * y, x, y, np.ones_like(x)])
    pinv = np.linalg.pinv(design)  # 6 x n^2: coefficients = pinv @ z
    kd = pinv[3].reshape(window, window)
    ke = pinv[4].reshape(window, window)
    return kd, ke


def wood_slope(dem: np.ndarray, cell: float, window: int = 5) -> np.ndarray:
    """Slope in degrees of ``dem`` (float, NaN = nodata) with a Wood quadratic fit.

    NaN cells are filled with their nearest valid value before fitting and are NaN
    again in the output; the grid border is extended by odd reflection.

    Parameters
    ----------
    dem : ndarray (H, W)
        Heights (m), NaN = no data.
    cell : float
        Cell size (m).
    window : int
        Side of the fitting window (cells), odd and at least 3.

    Returns
    -------
    ndarray (H, W) float32
        Slope (degrees), NaN where ``dem`` is NaN.
    """
    z = np.asarray(dem, dtype=np.float64)
    valid = np.isfinite(z)
    if not valid.any():
        return np.full(z.shape, np.nan, dtype=np.float32)
    z = fill_nearest(z)
    kd, ke = quadratic_kernels(window, cell)
    # odd reflection continues linear trends across the border, so edge cells keep
    # an unbiased gradient instead of the flattening a constant extension causes
    h = window // 2
    zp = np.pad(z, h, mode="reflect", reflect_type="odd") if min(z.shape) > h else np.pad(z, h, mode="edge")
    inner = (slice(h, h + z.shape[0]), slice(h, h + z.shape[1]))
    d = ndimage.correlate(zp, kd, mode="nearest")[inner]
    e = ndimage.correlate(zp, ke, mode="nearest")[inner]
    out = np.degrees(np.arctan(np.hypot(d, e))).astype(np.float32)
    out[~valid] = np.nan
    return out
