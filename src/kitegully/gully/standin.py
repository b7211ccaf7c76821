"""Evaluation stand-in for the photogrammetric DSM: the twin's truth DTM plus noise.

Twins only (gully.dem: truth_plus_noise), to evaluate the mapping apart from the DSM errors; it is NOT a photogrammetric product.
The noise is Gaussian white noise smoothed with a Gaussian of ``correlation_m`` and
rescaled to the requested standard deviation.
"""

from __future__ import annotations

import numpy as np
import scipy.ndimage as ndi

from kitegully.seeds import rng_for


def noisy_dem(dtm: np.ndarray, cell_m: float, sd_m: float, correlation_m: float, seed: int) -> np.ndarray:
    """``dtm`` plus spatially correlated Gaussian noise of standard deviation ``sd_m``.

    The generator is ``rng_for(seed, "gully", "standin_dem")`` (master seed of the config).
    Complexity O(n) (separable Gaussian filter); NaN cells stay NaN.

    Parameters
    ----------
    dtm : ndarray (H, W)
        The twin's truth DTM (m).
    cell_m : float
        Cell size (m).
    sd_m : float
        Standard deviation of the noise (m).
    correlation_m : float
        σ of the Gaussian that smooths the noise (m); 0: white noise.
    seed : int
        Master seed of the config.

    Returns
    -------
    ndarray (H, W) float32
        The stand-in DSM (m).
    """
    rng = rng_for(seed, "gully", "standin_dem")
    noise = rng.standard_normal(dtm.shape, dtype=np.float32)
    if correlation_m > 0:
        ndi.gaussian_filter(noise, correlation_m / cell_m, output=noise, mode="reflect")
        sd = float(noise.std(dtype=np.float64))
        if sd > 0:
            noise /= sd
    noise *= np.float32(sd_m)
    return (np.asarray(dtm, dtype=np.float32) + noise).astype(np.float32)
