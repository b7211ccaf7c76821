"""Automatic ExG threshold: the valley between two histogram peaks, Otsu alongside.

Mayr et al. (2016, sect. 2.4.2) find the two peaks of the (blurred) ExG histogram and
take the minimum between them; Otsu's threshold drifts towards the larger class.  The
peaks are found as ``skimage.filters.threshold_minimum`` finds them [I]: the histogram
is smoothed with a 3-bin mean until two maxima remain.  The valley is then the lowest
point between those two peaks of the histogram smoothed only by a Gaussian of
``valley_smoothing_bins`` (the middle of the lowest run where it is flat) [I]: the
repeated smoothing that isolates the peaks also spreads the larger class into the
valley and pushes its minimum towards the smaller class, and on a broad, flat valley
that shift depends on a handful of cells.  The histogram must then really be bimodal:
both sides of the valley must hold at least ``min_class_fraction`` of the cells and the
valley of the fully smoothed histogram must be at most ``max_valley_ratio`` x the lower
peak.  A histogram that fails is reported as not bimodal and no valley is returned: it
is never forced into two classes.

Before the peaks are sought, the outermost ``tail_fraction`` of the cells on each side is
cut off the histogram [I]: a kite orthophoto holds rare ExG outliers (deep shadow,
saturated roofs) far from the data, and those isolated counts would otherwise outlive
the smoothing as a "peak" while the real two modes merge into one.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage
from skimage.filters import threshold_otsu


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
    water_cells : int or None
        Cells masked as open water before the histogram (NDVI maps with
        ``water_ndvi_below``); None when no water mask was applied.
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
    water_cells: int | None = None

    def as_dict(self) -> dict:
        keys = ("valley", "otsu", "bimodal", "reason", "low_peak", "high_peak", "valley_ratio", "low_fraction")
        out = {k: getattr(self, k) for k in keys}
        if self.water_cells is not None:
            out["water_cells"] = self.water_cells
        return out


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


def _central_bins(counts: np.ndarray, tail_fraction: float) -> tuple[int, int]:
    """First and last bin of the histogram once ``tail_fraction`` of the cells is cut off each end."""
    cum = np.cumsum(counts)
    total = cum[-1]
    cut = tail_fraction * total
    lo = int(np.searchsorted(cum, cut, side="right"))
    hi = int(np.searchsorted(cum, total - cut, side="left"))
    return min(lo, hi), max(lo, hi)


def _middle_of_lowest_run(values: np.ndarray) -> int:
    """Index in the middle of the first run of the minimum value (the lower one of two middles)."""
    at_min = np.flatnonzero(values == values.min())
    breaks = np.flatnonzero(np.diff(at_min) > 1)
    last = at_min[breaks[0]] if breaks.size else at_min[-1]
    return int(at_min[0] + last) // 2


def find_thresholds(
    counts: np.ndarray,
    centres: np.ndarray,
    min_class_fraction: float,
    max_valley_ratio: float,
    max_iter: int = 10000,
    tail_fraction: float = 1e-3,
    valley_smoothing_bins: float = 2.0,
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
    tail_fraction
        Share of the cells cut off each end of the histogram before the peak search [I];
        the class fractions are still counted over all cells.
    valley_smoothing_bins
        Gaussian sigma (bins) of the histogram in which the valley is located [I]: enough
        to calm the Poisson noise of a sparse valley, far less than the peak search uses.
    """
    counts = np.asarray(counts, dtype=np.int64)
    centres = np.asarray(centres, dtype=np.float64)
    total = int(counts.sum())
    if total == 0:
        return ThresholdResult(None, None, False, "no valid values", counts=counts, centres=centres)
    otsu = float(threshold_otsu(hist=(counts, centres))) if np.count_nonzero(counts) > 1 else None
    lo, hi = _central_bins(counts, tail_fraction)
    # one empty bin each side, so that a mode at the cut still reads as a peak
    width = centres[1] - centres[0] if centres.size > 1 else 1.0
    trimmed = np.concatenate([[0], counts[lo:hi + 1], [0]])
    tcentres = np.concatenate([[centres[lo] - width], centres[lo:hi + 1], [centres[hi] + width]])
    smooth, maxima = _smooth_to_two_maxima(trimmed, max_iter)
    if len(maxima) != 2:
        return ThresholdResult(None, otsu, False, "the smoothed histogram has a single peak", counts=counts, centres=centres)
    i0, i1 = maxima
    ratio = float(smooth[i0:i1 + 1].min() / min(smooth[i0], smooth[i1]))
    light = ndimage.gaussian_filter1d(trimmed.astype(np.float64), valley_smoothing_bins, mode="constant")
    valley = float(tcentres[i0 + _middle_of_lowest_run(light[i0:i1 + 1])])
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
