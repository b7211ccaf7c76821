"""Evaluation stand-in for the photogrammetric DSM: the twin's truth DTM plus noise.

Used only until the dense-matching DSM exists; it is NOT a photogrammetric product.
The noise is Gaussian white noise smoothed with a Gaussian of ``correlation_m`` and
rescaled to the requested standard deviation.
"""

from __future__ import annotations

import zlib

import numpy as np
import scipy.ndimage as ndi

#: Tag mixed into the master seed so this stage's draws differ from other stages'.
SEED_TAG = zlib.crc32(b"gully.standin_dem")


def standin_seed(master_seed: int) -> np.random.SeedSequence:
    """Seed sequence of the stand-in noise derived from the master seed."""
    return np.random.SeedSequence([int(master_seed), SEED_TAG])


def noisy_dem(dtm: np.ndarray, cell_m: float, sd_m: float, correlation_m: float, seed: np.random.SeedSequence) -> np.ndarray:
    """``dtm`` plus spatially correlated Gaussian noise of standard deviation ``sd_m``.

    Complexity O(n) (separable Gaussian filter); NaN cells stay NaN.
    """
    rng = np.random.default_rng(seed)
    noise = rng.standard_normal(dtm.shape, dtype=np.float32)
    if correlation_m > 0:
        ndi.gaussian_filter(noise, correlation_m / cell_m, output=noise, mode="reflect")
        sd = float(noise.std(dtype=np.float64))
        if sd > 0:
            noise /= sd
    noise *= np.float32(sd_m)
    return (np.asarray(dtm, dtype=np.float32) + noise).astype(np.float32)
