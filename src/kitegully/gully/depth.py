"""Depth map (Feurer et al. 2018, Fig. 3 a-d): Gaussian-smoothed DEM minus the DEM."""

from __future__ import annotations

import numpy as np

from kitegully.terrain.smoothing import gaussian_smooth_fft


def depth_map(
    z: np.ndarray,
    cell_m: float,
    sigma_m: float,
    truncate: float = 4.0,
    workers: int = 1,
) -> tuple[np.ndarray, np.ndarray]:
    """Smoothed surface ``Zs`` and depth ``D = Zs − Z`` (positive below the smoothed surface).

    Parameters
    ----------
    z : ndarray (H, W)
        DEM (m), NaN nodata.
    cell_m : float
        Cell size (m).
    sigma_m : float
        Standard deviation of the Gaussian (m); the paper uses 10 m (2σ = widest gully).
    truncate : float
        Kernel radius and zero padding in σ.
    workers : int
        FFT threads.

    Returns
    -------
    smoothed, depth : ndarray (H, W) float32
        ``depth`` is NaN where ``z`` is NaN.

    Notes
    -----
    Complexity O(n log n); see :func:`kitegully.terrain.smoothing.gaussian_smooth_fft`.
    """
    smoothed = gaussian_smooth_fft(z, sigma_m / cell_m, truncate=truncate, workers=workers)
    depth = smoothed - np.asarray(z, dtype=np.float32)
    return smoothed, depth
