"""Vegetation indices: Excess Green on chromatic coordinates and NDVI.

ExG follows Woebbecke et al. (1995) as used by Mayr et al. (2016, eq. 1-4):
``ExG = 2g - r - b`` with ``r = R/(R+G+B)`` etc.  Because ``r + g + b = 1``,
``ExG = 3g - 1`` and lies in [-1, 2].  NDVI = (NIR - red)/(NIR + red) (Bryson et al. 2013).

Both are ratios of quantised bands: on an 8-bit orthophoto one digital number (DN) moves
ExG by about 2 / (R + G + B), 0.004 on soil of DN sum 500 (:func:`exg_step`,
:func:`ndvi_step`); a histogram binned finer than that shows the lattice of attainable
values, not the cover.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

EXG_RANGE = (-1.0, 2.0)
#: Range of NDVI, the fixed histogram range of an NDVI threshold.
NDVI_RANGE = (-1.0, 1.0)


def excess_green(red: np.ndarray, green: np.ndarray, blue: np.ndarray) -> np.ndarray:
    """Excess Green index per cell, float32.

    Parameters
    ----------
    red, green, blue
        Bands of equal shape, any non-negative scale (DN or reflectance).  NaN
        propagates.  Where ``R + G + B == 0`` (black) ExG is 0 [I].

    Returns
    -------
    numpy.ndarray
        ExG in [-1, 2].
    """
    r = np.asarray(red, dtype=np.float32)
    g = np.asarray(green, dtype=np.float32)
    b = np.asarray(blue, dtype=np.float32)
    total = r + g + b
    with np.errstate(invalid="ignore", divide="ignore"):
        exg = (2.0 * g - r - b) / total
    exg[total == 0] = 0.0
    return exg.astype(np.float32)


def dn_step(dtype: np.dtype | str) -> float:
    """Smallest change a band of this data type can record: 1 DN for integer types, 0 for
    floating point (no quantisation known) [I]."""
    return 1.0 if np.issubdtype(np.dtype(dtype), np.integer) else 0.0


def exg_step(red: np.ndarray, green: np.ndarray, blue: np.ndarray, step: float = 1.0) -> np.ndarray:
    """Largest change of ExG that one ``step`` of a single band makes, per cell (float32).

    With S = R + G + B, dExG/dG = (2 - ExG)/S and dExG/dR = dExG/dB = -(1 + ExG)/S, so
    the step is ``step * max(2 - ExG, 1 + ExG) / S``: about 2 / S on soil (ExG near 0).
    O(N).

    Parameters
    ----------
    red, green, blue : ndarray
        Bands of equal shape in DN.
    step : float
        One quantisation step of the bands (:func:`dn_step`; 0 for unquantised data).

    Returns
    -------
    ndarray float32
        The ExG step; 0 where S == 0, NaN where a band is NaN.
    """
    r = np.asarray(red, dtype=np.float32)
    g = np.asarray(green, dtype=np.float32)
    b = np.asarray(blue, dtype=np.float32)
    total = r + g + b
    e = excess_green(r, g, b)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = step * np.maximum(2.0 - e, 1.0 + e) / total
    out[total == 0] = 0.0
    return out.astype(np.float32)


def ndvi_step(nir: np.ndarray, red: np.ndarray, nir_step: float = 1.0, red_step: float = 1.0) -> np.ndarray:
    """Largest change of NDVI that one quantisation step of NIR or red makes, per cell (float32).

    dNDVI/dNIR = 2 red / (NIR + red)^2 and dNDVI/dred = -2 NIR / (NIR + red)^2. O(N).

    Parameters
    ----------
    nir, red : ndarray
        Bands of equal shape in DN.
    nir_step, red_step : float
        One quantisation step of each band (:func:`dn_step`).

    Returns
    -------
    ndarray float32
        The NDVI step; 0 where NIR + red == 0, NaN where a band is NaN.
    """
    n = np.asarray(nir, dtype=np.float32)
    r = np.asarray(red, dtype=np.float32)
    total = n + r
    with np.errstate(invalid="ignore", divide="ignore"):
        out = 2.0 * np.maximum(nir_step * r, red_step * n) / (total * total)
    out[total == 0] = 0.0
    return out.astype(np.float32)


def blue_dominant(red: np.ndarray, green: np.ndarray, blue: np.ndarray) -> np.ndarray:
    """Cells whose blue band is brighter than both red and green (bool).

    Neither soil nor plants look like this [I]: iron oxides and organic matter make soil
    reflectance rise from blue to red, and plant material, green (chlorophyll) or
    senescent (carotenoids, lignin), absorbs blue more than green or red.  Blue is the
    brightest band over open water (red absorbed by water), in shade lit by the blue sky
    and on some painted roofs.  Such cells form their own ExG mode (open water sits
    between bare soil and vegetation) and are left out of the threshold histogram.
    O(N).

    Parameters
    ----------
    red, green, blue : ndarray
        Bands of equal shape, any scale (DN or reflectance).

    Returns
    -------
    ndarray bool
        True where blue exceeds both red and green; False where any band is NaN.
    """
    r = np.asarray(red, dtype=np.float32)
    g = np.asarray(green, dtype=np.float32)
    b = np.asarray(blue, dtype=np.float32)
    return (b > r) & (b > g)


def ndvi(nir: np.ndarray, red: np.ndarray) -> np.ndarray:
    """Normalised difference vegetation index, float32; 0 where NIR + red == 0 [I]."""
    n = np.asarray(nir, dtype=np.float32)
    r = np.asarray(red, dtype=np.float32)
    total = n + r
    with np.errstate(invalid="ignore", divide="ignore"):
        out = (n - r) / total
    out[total == 0] = 0.0
    return out.astype(np.float32)


def local_range(values: np.ndarray, size: int) -> np.ndarray:
    """Max minus min of ``values`` over each cell's ``size`` x ``size`` neighbourhood (float32).

    A cell with a NaN neighbour gets +inf (its neighbourhood is not known whole). O(N * size).

    Parameters
    ----------
    values : ndarray (H, W)
        Values; NaN = no data.
    size : int
        Window side (cells, odd).

    Returns
    -------
    ndarray (H, W) float32
        The local range; NaN where ``values`` is NaN.
    """
    v = np.asarray(values, dtype=np.float32)
    valid = np.isfinite(v)
    hi = ndimage.maximum_filter(np.where(valid, v, np.inf), size=size, mode="nearest")
    lo = ndimage.minimum_filter(np.where(valid, v, -np.inf), size=size, mode="nearest")
    out = (hi - lo).astype(np.float32)
    out[~valid] = np.nan
    return out


def gaussian_blur(values: np.ndarray, sigma_cells: float, radius_cells: int) -> np.ndarray:
    """Gaussian filter with a truncated kernel, NaN-aware (normalised convolution).

    Mayr et al. blur ExG with sigma = 1 and search radius r = 2 (a 5x5 kernel).
    Cells that are NaN stay NaN; valid cells next to NaN are averaged over their
    valid neighbours only.  O(N * radius) (separable filter).

    Parameters
    ----------
    values : ndarray (H, W)
        Values to blur; NaN = no data.
    sigma_cells : float
        Standard deviation of the Gaussian (cells); 0 or less returns an unblurred copy.
    radius_cells : int
        Kernel radius (cells).

    Returns
    -------
    ndarray (H, W) float32
        Blurred values, NaN where ``values`` is NaN.
    """
    v = np.asarray(values, dtype=np.float32)
    valid = np.isfinite(v)
    if sigma_cells <= 0:
        return v.copy()
    filled = np.where(valid, v, 0.0).astype(np.float32)
    kw = dict(sigma=sigma_cells, radius=int(radius_cells), mode="nearest")
    num = ndimage.gaussian_filter(filled, **kw)
    den = ndimage.gaussian_filter(valid.astype(np.float32), **kw)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = num / den
    out[~valid] = np.nan
    return out.astype(np.float32)
