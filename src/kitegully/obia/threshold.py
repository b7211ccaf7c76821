"""Automatic ExG threshold: the valley between two histogram peaks, Otsu alongside.

Mayr et al. (2016, sect. 2.4.2) find the two peaks of the (blurred) ExG histogram and
take the minimum between them; Otsu's threshold drifts towards the larger class.  We
use ``skimage.filters.threshold_minimum`` [I] (it smooths the histogram with a 3-bin
mean until two maxima remain and returns the valley) and then check that the histogram
really is bimodal: both sides of the valley must hold at least ``min_class_fraction``
of the cells and the smoothed valley must be at most ``max_valley_ratio`` x the lower
peak.  A histogram that fails is reported as not bimodal and no valley is returned:
it is never forced into two classes.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage
from skimage.filters import threshold_minimum, threshold_otsu


@dataclass
class ThresholdResult:
    """Outcome of the threshold search on one histogram.

    Attributes
    ----------
    valley : float or None
        Valley threshold; None when the histogram is not bimodal.
    otsu : float or None
        Otsu's threshold (always computed when there are values; for comparison).
    bimodal : bool
    reason : str
        Why the histogram counts as (not) bimodal, one sentence.
    low_peak, high_peak : float or None
        Bin centres of the two peaks of the smoothed histogram.
    valley_ratio : float or None
        Smoothed count at the valley / the lower of the two peaks.
    low_fraction : float or None
        Share of cells at or below the valley.
    counts, centres : numpy.ndarray
        The (unsmoothed) histogram.
    """

    valley: float | None
    otsu: float | None
    bimodal: bool
    reason: str
    low_peak: float | None = None
    high_peak: float | None = None
    valley_ratio: float | None = None
    low_fraction: float | None = None
    counts: np.ndarray = field(default_factory=lambda: np.zeros(0))
    centres: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def as_dict(self) -> dict:
        keys = ("valley", "otsu", "bimodal", "reason", "low_peak", "high_peak", "valley_ratio", "low_fraction")
        return {k: getattr(self, k) for k in keys}


def histogram(values: np.ndarray, bins: int, value_range: tuple[float, float] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Histogram of the finite values: (counts, bin centres)."""
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v)]
    if value_range is None:
        value_range = (float(v.min()), float(v.max())) if v.size else (0.0, 1.0)
        if value_range[0] == value_range[1]:
            value_range = (value_range[0] - 0.5, value_range[1] + 0.5)
    counts, edges = np.histogram(v, bins=bins, range=value_range)
    return counts.astype(np.int64), (0.5 * (edges[:-1] + edges[1:]))


def _local_maxima(hist: np.ndarray) -> list[int]:
    """Maxima as skimage's threshold_minimum counts them (plateau-safe)."""
    idx = []
    rising = True
    for i in range(hist.shape[0] - 1):
        if rising and hist[i + 1] < hist[i]:
            rising = False
            idx.append(i)
        elif not rising and hist[i + 1] > hist[i]:
            rising = True
    return idx


def _smooth_to_two_maxima(counts: np.ndarray, max_iter: int) -> tuple[np.ndarray, list[int]]:
    """Repeat skimage's 3-bin smoothing until fewer than 3 maxima remain."""
    smooth = counts.astype(np.float32)
    maxima: list[int] = []
    for _ in range(max_iter):
        smooth = ndimage.uniform_filter1d(smooth, 3)
        maxima = _local_maxima(smooth)
        if len(maxima) < 3:
            break
    return smooth, maxima


def find_thresholds(
    counts: np.ndarray,
    centres: np.ndarray,
    min_class_fraction: float,
    max_valley_ratio: float,
    max_iter: int = 10000,
) -> ThresholdResult:
    """Valley and Otsu thresholds of a histogram, with the bimodality check.

    Parameters
    ----------
    counts, centres
        Histogram counts and bin centres (see :func:`histogram`).
    min_class_fraction
        Least share of all cells each side of the valley must hold [I].
    max_valley_ratio
        Largest allowed (smoothed valley count) / (lower peak count) [I].
    """
    counts = np.asarray(counts, dtype=np.int64)
    centres = np.asarray(centres, dtype=np.float64)
    total = int(counts.sum())
    if total == 0:
        return ThresholdResult(None, None, False, "no valid values", counts=counts, centres=centres)
    otsu = float(threshold_otsu(hist=(counts, centres))) if np.count_nonzero(counts) > 1 else None
    try:
        valley = float(threshold_minimum(hist=(counts, centres), max_num_iter=max_iter))
    except RuntimeError:
        return ThresholdResult(None, otsu, False, "the smoothed histogram has a single peak", counts=counts, centres=centres)
    nz = np.flatnonzero(counts)
    trimmed = counts[nz[0]: nz[-1] + 1]
    tcentres = centres[nz[0]: nz[-1] + 1]
    smooth, maxima = _smooth_to_two_maxima(trimmed, max_iter)
    if len(maxima) != 2:
        return ThresholdResult(None, otsu, False, "the smoothed histogram has a single peak", counts=counts, centres=centres)
    i0, i1 = maxima
    ratio = float(smooth[i0:i1 + 1].min() / min(smooth[i0], smooth[i1]))
    low_fraction = float(counts[centres <= valley].sum() / total)
    res = ThresholdResult(
        valley, otsu, True, "two peaks separated by a valley",
        low_peak=float(tcentres[i0]), high_peak=float(tcentres[i1]),
        valley_ratio=ratio, low_fraction=low_fraction, counts=counts, centres=centres,
    )
    if min(low_fraction, 1.0 - low_fraction) < min_class_fraction:
        res.bimodal = False
        res.valley = None
        res.reason = (f"one side of the valley holds only {100 * min(low_fraction, 1 - low_fraction):.2f} % of the cells "
                      f"(< {100 * min_class_fraction:.2f} %)")
    elif ratio > max_valley_ratio:
        res.bimodal = False
        res.valley = None
        res.reason = f"the valley is too shallow (valley/peak = {ratio:.2f} > {max_valley_ratio:.2f})"
    return res
