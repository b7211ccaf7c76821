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

Lowest mode (:func:`find_bare_threshold`) [I]: a histogram may hold more than two cover
types, for example bare soil, senescent (straw-coloured) grass and green shrubs.  The
peak search above keeps the two strongest modes and then puts the valley between
"soil + straw" and "green", so dry grass is mapped as bare.  Every plant surface,
green or senescent, reflects more green relative to red and blue than soil does
(chlorophyll peak at 550 nm; straw keeps carotenoids and lignin, G close to R, while
iron-oxide soils have R > G > B [I]), so bare soil is the LOWEST ExG mode.  The split is
therefore repeated on the cells below the valley, re-binned into ``bins`` bins over the
range they occupy (finer bins: soil at ExG 0.00 and straw at 0.05 are a few of the
first histogram's bins apart), with the same bimodality tests plus a 3-sigma Poisson
test of the dip, as long as that lower part is itself bimodal; the last valley found
bounds the lowest mode.  A two-class scene (grass over soil) has a unimodal lower part
and keeps the first valley.

Index resolution [I]: the bands of an orthophoto are quantised (8 bits as a rule), so the
index takes a lattice of values whose spacing is the change one digital number makes, about
2 / (R + G + B) for ExG on soil (:func:`kitegully.obia.indices.exg_step`): 0.004 on soil of
DN sum 500.  The 5 x 5 blur does not dissolve it, because neighbouring cells of smooth soil
carry the same DN.  Re-binned finer than that, the histogram of one soil is a comb whose
beat pattern reads as two modes (a 600 x 400 m corner of the full-size Kamech twin, GSD
9.6 cm, split its ploughed soil 0.0066 apart and lost half of it to "vegetation", session
41).  Where the one-DN steps of the cells are known (``fine_steps``), no re-binned bin is
narrower than their mean over the part re-binned: two modes closer than what one DN can
express are not told apart.  The first histogram (``bins`` bins over the whole range, the
paper's) is left as it is: its bins are several steps wide over the kite's fixed range.

Mixed cells [I]: the blur turns a sharp boundary between two covers into a ramp of cells
whose values lie between the two modes, and on clean boundaries those cells cluster at the
few values the 5 x 5 kernel can give (a bump 1-2 % of a small scene; the descent took such a
bump for a third cover on synthetic scenes).  A cover type is made of cells whose neighbours
carry nearly their own value; a boundary cell has neighbours on both sides.  A further split
is therefore kept only where each side holds ``min_class_fraction`` of all cells among the
cells whose local range (max - min of the blurred index over the cells within one blur sigma,
:func:`kitegully.obia.indices.local_range`) is at most half the distance between the two
peaks: a cell spanning more than that mixes them.  On the dry-straw twins 13-18 % of all cells
pass on the straw side; on the synthetic scenes' edge bumps none do.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy import ndimage
from skimage.filters import threshold_otsu

STEP_UNIT = 1e-7
"""Fixed-point unit of the summed one-DN index steps per fine bin (:attr:`IndexHistogram.step_sums`) [I]:
integer sums are exact, so a site's histogram tiles add up to the same threshold in any order, and
1e-7 is more than two orders below the one-DN step of a 16-bit orthophoto's ExG on soil (2 / 60 000)."""

RANGE_EDGES = np.concatenate([[0.0], np.geomspace(1e-4, 3.0, 48)])
"""Bin edges of a cell's local range in :class:`IndexHistogram` [I]: 1e-4 is below the one-DN step of
any 8- to 12-bit orthophoto's index, 3 is the width of ExG's whole range, and successive edges 24 %
apart resolve the half peak distance of the mixed-cell test to a quarter; larger ranges (next to no
data: infinite) fall in the last bin."""

FINE_BINS_PER_BIN = 64
"""Fine bins per histogram bin [I]: 256 x 64 bins over ExG [-1, 2] are 0.00018 wide, far below
the spread of one cover type (~0.01), so re-binning the fine histogram over any part of the
range gives the histogram a pass over that part's own range would give."""


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
    valleys : list of float
        Every valley found by :func:`find_bare_threshold`, from the first (two strongest
        modes) down to the one bounding the lowest mode; empty for :func:`find_thresholds`.
    low_fraction : float or None
        Share of cells at or below the valley.
    counts, centres : numpy.ndarray
        The (unsmoothed) histogram.
    index_step : float or None
        Mean one-DN index step of the cells below the first valley, the narrowest bin of
        their re-binned histogram; None where the steps are not known or nothing was re-binned.
    stop_reason : str or None
        Why :func:`find_bare_threshold` split no further, one sentence; None elsewhere.
    water_cells : int or None
        Cells of a kite-scale map left unclassified as open water (segments mostly
        blue-dominant, or of blurred NDVI below ``water_ndvi_below``); None where no map was made.
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
    valleys: list = field(default_factory=list)
    index_step: float | None = None
    stop_reason: str | None = None

    def as_dict(self) -> dict:
        """The thresholds and their diagnostics as a dict, without the histogram (``water_cells``,
        ``index_step`` and ``stop_reason`` only when set)."""
        keys = ("valley", "otsu", "bimodal", "reason", "low_peak", "high_peak", "valley_ratio", "low_fraction", "valleys")
        out = {k: getattr(self, k) for k in keys}
        for k in ("water_cells", "index_step", "stop_reason"):
            if getattr(self, k) is not None:
                out[k] = getattr(self, k)
        return out


def _finite_with_range(values: np.ndarray, value_range: tuple[float, float] | None) -> tuple[np.ndarray, tuple[float, float]]:
    """The finite values as float64 and the histogram range: ``value_range`` or the data's own
    (min, max), widened by 0.5 either side when all values are equal."""
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v)]
    if value_range is None:
        value_range = (float(v.min()), float(v.max())) if v.size else (0.0, 1.0)
        if value_range[0] == value_range[1]:
            value_range = (value_range[0] - 0.5, value_range[1] + 0.5)
    return v, value_range


def histogram(values: np.ndarray, bins: int, value_range: tuple[float, float] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Histogram of the finite values: (counts, bin centres).

    Parameters
    ----------
    values : ndarray
        Values of any shape; NaN and infinite values are left out.
    bins : int
        Number of equal bins.
    value_range : tuple of float or None
        (min, max) of the bins; None takes the data's own range, widened by 0.5 either
        side when all values are equal.

    Returns
    -------
    counts : ndarray int64 (bins,)
        Cells per bin.
    centres : ndarray (bins,)
        Bin centres.
    """
    v, value_range = _finite_with_range(values, value_range)
    counts, edges = np.histogram(v, bins=bins, range=value_range)
    return counts.astype(np.int64), (0.5 * (edges[:-1] + edges[1:]))


def central_histogram(counts: np.ndarray, edges: np.ndarray, bins: int, tail_fraction: float = 1e-3,
                      min_width: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Re-bin a fine histogram into at most ``bins`` bins over the range its central cells occupy.

    A scene's histogram spans the data's own range (:func:`histogram`); a site-wide
    histogram is accumulated tile by tile on a fixed fine grid over the whole ExG range
    and re-binned here, so that its ``bins`` bins also span the data and not the
    theoretical [-1, 2] [I].  The range is that of the cells left once ``tail_fraction``
    is cut off each end (rare outliers in deep shadow or on roofs would otherwise widen
    it and coarsen the bins); the cut-off cells are counted in the end bins.  Each new bin
    is the smallest whole number of fine bins that keeps the count at most ``bins`` (so
    between ``bins``/2 and ``bins`` bins when the range spans more than ``bins`` fine bins),
    and at least ``min_width`` wide.

    Parameters
    ----------
    counts, edges
        Fine histogram: counts (n) and bin edges (n + 1), equal widths.
    bins
        Largest number of bins over the central range.
    tail_fraction
        Share of the cells cut off each end [I] (as in :func:`find_thresholds`).
    min_width
        Narrowest new bin (the index's resolution, see the module notes); 0 for no bound.

    Returns
    -------
    (counts, centres)
        The re-binned histogram.
    """
    counts = np.asarray(counts, dtype=np.int64)
    if counts.sum() == 0:
        return counts, 0.5 * (edges[:-1] + edges[1:])
    lo, hi = _central_bins(counts, tail_fraction)
    width = float(edges[1] - edges[0])
    group = max(1, int(np.ceil((hi - lo + 1) / bins)), int(np.ceil(min_width / width - 1e-9)))
    n = int(np.ceil((hi - lo + 1) / group))
    start = max(0, min(lo, counts.size - n * group))
    stop = start + n * group
    pad = max(0, stop - counts.size)
    fine = np.concatenate([counts, np.zeros(pad, dtype=np.int64)])
    out = fine[start:stop].reshape(n, group).sum(axis=1)
    out[0] += counts[:start].sum()
    out[-1] += counts[stop:].sum() if stop < counts.size else 0
    new_edges = edges[0] + width * (start + group * np.arange(n + 1))
    return out, 0.5 * (new_edges[:-1] + new_edges[1:])


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


def _smooth_to_two_maxima(counts: np.ndarray, max_iter: int) -> tuple[np.ndarray, list[int], list[tuple[np.ndarray, list[int]]]]:
    """Repeat skimage's 3-bin smoothing until fewer than 3 maxima remain.

    Returns the final smoothed histogram and its maxima, and every earlier level at which the
    number of maxima (3 or more) changed, most smoothed first: ``(smoothed, maxima)``.
    """
    smooth = counts.astype(np.float32)
    maxima: list[int] = []
    earlier: list[tuple[np.ndarray, list[int]]] = []
    for _ in range(max_iter):
        smooth = ndimage.uniform_filter1d(smooth, 3)
        maxima = _local_maxima(smooth)
        if len(maxima) < 3:
            break
        if not earlier or len(earlier[-1][1]) != len(maxima):
            earlier.append((smooth.copy(), maxima))
    return smooth, maxima, earlier[::-1]


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
    open_high: bool = False,
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
    open_high
        The histogram ends at an earlier valley (the part below it, :func:`find_bare_threshold`):
        a rise at its high end is the flank of the mode above that valley, not a mode, so the
        high end is not closed with an empty bin and cannot read as a peak [I].

    Returns
    -------
    ThresholdResult
        The valley and its tests. The histogram is smoothed until two maxima remain (skimage's
        ``threshold_minimum``, the paper's two-peak valley). Where that split fails a test and
        the histogram held three or more modes on the way (soil, grass and shrubs: the smoothing
        that merges the upper two also fills the valley above the narrow soil mode), the valley
        is the lowest one of the most smoothed earlier level that passes the same tests and whose
        dip exceeds counting noise (:data:`DIP_SIGMAS`) [I]; its ``reason`` says so. Not with
        ``open_high``.
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
    high = [] if open_high else [0]
    trimmed = np.concatenate([[0], counts[lo:hi + 1], high])
    tcentres = np.concatenate([[centres[lo] - width], centres[lo:hi + 1], [centres[hi] + width] * len(high)])
    smooth, maxima, earlier = _smooth_to_two_maxima(trimmed, max_iter)
    light = ndimage.gaussian_filter1d(trimmed.astype(np.float64), valley_smoothing_bins, mode="constant")

    def split(level: np.ndarray, i0: int, i1: int, reason: str) -> ThresholdResult:
        ratio = float(level[i0:i1 + 1].min() / min(level[i0], level[i1]))
        valley = float(tcentres[i0 + _middle_of_lowest_run(light[i0:i1 + 1])])
        low_fraction = float(counts[centres <= valley].sum() / total)
        res = ThresholdResult(valley, otsu, True, reason, low_peak=float(tcentres[i0]), high_peak=float(tcentres[i1]),
                              valley_ratio=ratio, low_fraction=low_fraction, counts=counts, centres=centres)
        if min(low_fraction, 1.0 - low_fraction) < min_class_fraction:
            res.bimodal, res.valley = False, None
            res.reason = (f"one side of the valley holds only {100 * min(low_fraction, 1 - low_fraction):.2f} % of the cells "
                          f"(< {100 * min_class_fraction:.2f} %)")
        elif ratio > max_valley_ratio:
            res.bimodal, res.valley = False, None
            res.reason = f"the valley is too shallow (valley/peak = {ratio:.2f} > {max_valley_ratio:.2f})"
        return res

    if len(maxima) == 2:
        res = split(smooth, maxima[0], maxima[1], "two peaks separated by a valley")
    else:
        res = ThresholdResult(None, otsu, False, "the smoothed histogram has a single peak", counts=counts, centres=centres)
    if res.bimodal or open_high:
        return res
    # More than two modes (soil, grass, shrubs): merging the upper ones smooths the lowest
    # valley away. Take the most smoothed earlier level whose lowest valley passes the same
    # tests and is no counting noise. (A part below a valley, ``open_high``, is not searched
    # so: there :func:`find_bare_threshold`'s own tests decide.)
    for level, peaks in earlier:
        alt = split(level, peaks[0], peaks[1], f"lowest valley of {len(peaks)} smoothed peaks (the two-peak split: {res.reason})")
        if alt.bimodal and _dip_is_significant(trimmed, tcentres, alt.valley, alt.high_peak):
            return alt
    return res


DIP_SIGMAS = 3.0
"""A further split needs a dip of at least 3 Poisson standard deviations [I] (the usual
significance convention): a bump of counting noise on a flat tail is no mode."""


def _dip_is_significant(counts: np.ndarray, centres: np.ndarray, valley: float, peak: float, sigmas: float = DIP_SIGMAS) -> bool:
    """True if the counts around ``peak`` exceed those around ``valley`` by ``sigmas`` Poisson SDs.

    Both windows are half the valley-peak distance wide on each side (so they do not
    overlap); N_peak - N_valley > sigmas x sqrt(N_peak + N_valley) [I].
    """
    half = 0.5 * abs(peak - valley)
    n_peak = float(counts[np.abs(centres - peak) <= half].sum())
    n_valley = float(counts[np.abs(centres - valley) <= half].sum())
    return n_peak - n_valley > sigmas * np.sqrt(max(n_peak + n_valley, 1.0))


def fine_histogram(values: np.ndarray, bins: int, value_range: tuple[float, float] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Histogram of the finite values on ``bins`` x :data:`FINE_BINS_PER_BIN` fine bins: (counts, edges).

    The range is ``value_range`` or the data's own (min, max), as :func:`histogram` takes it;
    grouping every :data:`FINE_BINS_PER_BIN` fine bins gives exactly :func:`histogram`'s
    ``bins`` bins.

    Parameters
    ----------
    values : ndarray
        Values of any shape; NaN and infinite values are left out.
    bins : int
        Number of histogram bins; the fine histogram has :data:`FINE_BINS_PER_BIN` times as many.
    value_range : tuple of float or None
        (min, max) of the bins; None takes the data's own range.

    Returns
    -------
    counts : ndarray int64 (bins x FINE_BINS_PER_BIN,)
        Cells per fine bin.
    edges : ndarray (bins x FINE_BINS_PER_BIN + 1,)
        Fine bin edges.
    """
    v, value_range = _finite_with_range(values, value_range)
    counts, edges = np.histogram(v, bins=bins * FINE_BINS_PER_BIN, range=value_range)
    return counts.astype(np.int64), edges


@dataclass
class IndexHistogram:
    """Fine histogram of the blurred index with what the lowest-mode descent needs beside the counts.

    Attributes
    ----------
    by_range : ndarray int64 (fine bins, len(RANGE_EDGES) - 1)
        Cells per fine bin and local-range bin (:data:`RANGE_EDGES`).
    step_sums : ndarray int64 (fine bins,)
        Per fine bin, the cells' summed one-DN index steps in units of :data:`STEP_UNIT`
        (integers, so that sums over tiles are exact in any order).
    quantised : bool
        Whether the bands are integers, so that the steps mean something.
    """

    by_range: np.ndarray
    step_sums: np.ndarray
    quantised: bool = True

    @classmethod
    def zeros(cls, fine_bins: int, quantised: bool = True) -> "IndexHistogram":
        """An empty histogram of ``fine_bins`` fine bins."""
        return cls(np.zeros((fine_bins, RANGE_EDGES.size - 1), dtype=np.int64), np.zeros(fine_bins, dtype=np.int64), quantised)

    @classmethod
    def of(cls, values: np.ndarray, steps: np.ndarray, ranges: np.ndarray, edges: np.ndarray,
           quantised: bool = True) -> "IndexHistogram":
        """The histogram of the finite ``values`` on the fine ``edges``. O(N).

        Parameters
        ----------
        values : ndarray
            Blurred index; NaN and infinite values are left out.
        steps : ndarray
            Each cell's one-DN index step (:func:`kitegully.obia.indices.exg_step`), same shape.
        ranges : ndarray
            Each cell's local range (:func:`kitegully.obia.indices.local_range`), same shape.
        edges : ndarray
            Fine bin edges (:func:`fine_histogram`); bins as :func:`numpy.histogram` makes them.
        quantised : bool
            Whether ``steps`` are known (integer bands).

        Returns
        -------
        IndexHistogram
        """
        v = np.asarray(values, dtype=np.float64).ravel()
        edges = np.asarray(edges, dtype=np.float64)
        n = edges.size - 1
        ok = np.isfinite(v) & (v >= edges[0]) & (v <= edges[-1])
        v = v[ok]
        fine = np.minimum(np.searchsorted(edges, v, side="right") - 1, n - 1)  # np.histogram's bins
        r = np.nan_to_num(np.asarray(ranges, dtype=np.float64).ravel()[ok], nan=np.inf)
        nr = RANGE_EDGES.size - 1
        rbin = np.clip(np.searchsorted(RANGE_EDGES, r, side="right") - 1, 0, nr - 1)
        by_range = np.bincount(fine * nr + rbin, minlength=n * nr).reshape(n, nr).astype(np.int64)
        q = np.nan_to_num(np.asarray(steps, dtype=np.float64).ravel()[ok], nan=0.0)
        step_sums = np.bincount(fine, weights=np.rint(q / STEP_UNIT), minlength=n)
        return cls(by_range, np.rint(step_sums).astype(np.int64), quantised)

    def save(self, path: str | Path, **extra) -> None:
        """Write the histogram sparsely (nonzero cells only) to ``path`` (.npz), with ``extra`` arrays beside it."""
        fine, rng = np.nonzero(self.by_range)
        nz = np.flatnonzero(self.step_sums)
        np.savez_compressed(path, fine=fine.astype(np.int32), range_bin=rng.astype(np.int16), count=self.by_range[fine, rng],
                            step_bin=nz.astype(np.int32), step_sum=self.step_sums[nz], shape=np.array(self.by_range.shape),
                            quantised=self.quantised, **extra)

    @classmethod
    def load(cls, path: str | Path) -> "IndexHistogram":
        """Read a histogram written by :meth:`save`; KeyError if ``path`` holds none."""
        with np.load(path) as z:
            by_range = np.zeros(tuple(int(v) for v in z["shape"]), dtype=np.int64)
            by_range[z["fine"], z["range_bin"]] = z["count"]
            steps = np.zeros(by_range.shape[0], dtype=np.int64)
            steps[z["step_bin"]] = z["step_sum"]
            return cls(by_range, steps, bool(z["quantised"]))

    @property
    def counts(self) -> np.ndarray:
        """Cells per fine bin (int64)."""
        return self.by_range.sum(axis=1)

    def __iadd__(self, other: "IndexHistogram") -> "IndexHistogram":
        self.by_range += other.by_range
        self.step_sums += other.step_sums
        self.quantised = self.quantised and other.quantised
        return self


def find_bare_threshold(
    fine_counts: np.ndarray,
    fine_edges: np.ndarray,
    bins: int,
    min_class_fraction: float,
    max_valley_ratio: float,
    max_splits: int = 8,
    fine_steps: np.ndarray | None = None,
    fine_by_range: np.ndarray | None = None,
) -> ThresholdResult:
    """Valley that bounds the lowest ExG mode (bare soil) of a possibly multimodal histogram.

    The first split is :func:`find_thresholds` on the fine histogram grouped into ``bins``
    bins over its whole range (exactly the paper's two-peak valley on ``bins`` bins).  While
    a valley is found, the cells at or below it are re-binned into ``bins`` bins over the
    range they occupy (:func:`central_histogram`; finer bins, so that two close modes such
    as soil at ExG 0.0 and straw at 0.05 are resolved) and searched again with the same
    tests; each side of a new valley must also hold ``min_class_fraction`` of ALL cells,
    and the dip must be significant against counting noise (:data:`DIP_SIGMAS`).
    With ``fine_steps``, no re-binned bin is narrower than the mean one-DN index step of
    the cells re-binned (module notes: the index's resolution); with ``fine_by_range``,
    each side of a further split must hold ``min_class_fraction`` of all cells among the
    cells whose local range is at most half the distance between its two peaks (module
    notes: mixed cells).  ``stop_reason`` says why the descent ended.
    The result is the last valid split: its ``valley``, peaks, ratio and ``low_fraction``
    (of all cells) describe the lowest mode and the mode just above it; ``valleys`` lists
    every valley from the first to the last; ``otsu``, ``counts`` and ``centres`` are those
    of the first (``bins``-bin) histogram.  A histogram that is not bimodal at the first
    split is returned as :func:`find_thresholds` returns it.

    Parameters
    ----------
    fine_counts, fine_edges
        Fine histogram with ``bins`` x k equal bins (:func:`fine_histogram`).
    bins
        Bins of the first histogram and of each re-binned lower part [I].
    min_class_fraction, max_valley_ratio
        As in :func:`find_thresholds` [I].
    max_splits
        Safety bound on the number of further splits (each removes at least one mode).
    fine_steps
        Per fine bin, the summed one-DN index steps of its cells in :data:`STEP_UNIT`
        (:attr:`IndexHistogram.step_sums`); None where the bands' quantisation is not known.
    fine_by_range
        Cells per fine bin and local-range bin (:attr:`IndexHistogram.by_range`); None
        skips the mixed-cell test.

    Complexity: O(fine bins + max_splits x bins x smoothing iterations).
    """
    fine_counts = np.asarray(fine_counts, dtype=np.int64)
    fine_edges = np.asarray(fine_edges, dtype=np.float64)
    group = fine_counts.size // bins
    if group < 1 or group * bins != fine_counts.size:
        raise ValueError(f"fine histogram of {fine_counts.size} bins is not a multiple of {bins} bins")
    counts = fine_counts.reshape(bins, group).sum(axis=1)
    coarse_edges = fine_edges[::group]
    centres = 0.5 * (coarse_edges[:-1] + coarse_edges[1:])
    fine_centres = 0.5 * (fine_edges[:-1] + fine_edges[1:])
    total = int(fine_counts.sum())
    best = find_thresholds(counts, centres, min_class_fraction, max_valley_ratio)
    if best.valley is None:
        return best
    valleys = [best.valley]
    steps = None if fine_steps is None else np.asarray(fine_steps, dtype=np.float64) * STEP_UNIT
    first_step = None
    stop = f"stopped after {max_splits} further splits"
    for _ in range(max_splits):
        keep = fine_centres <= best.valley
        if keep.sum() < 2:
            stop = "no cells below the last valley"
            break
        min_width = 0.0
        if steps is not None:
            min_width = float(steps[keep].sum() / max(int(fine_counts[keep].sum()), 1))
            first_step = min_width if first_step is None else first_step
        sub_counts, sub_centres = central_histogram(fine_counts[keep], fine_edges[:int(keep.sum()) + 1], bins,
                                                    min_width=min_width)
        sub = find_thresholds(sub_counts, sub_centres, min_class_fraction, max_valley_ratio, open_high=True)
        where = f"the cells below {best.valley:.4g}"
        if sub.valley is None or sub.valley >= best.valley:
            stop = f"{where} are not bimodal ({sub.reason})"
            break
        lower = fine_centres <= sub.valley
        below = int(fine_counts[lower].sum())
        above = int(fine_counts[keep].sum()) - below
        if min(below, above) < min_class_fraction * total:
            stop = f"{where}: one side of {sub.valley:.4g} holds < {100 * min_class_fraction:g} % of all cells"
            break
        if not _dip_is_significant(sub_counts, sub_centres, sub.valley, sub.high_peak):
            stop = f"{where}: the dip at {sub.valley:.4g} is within counting noise"
            break
        if fine_by_range is not None:
            half = 0.5 * (sub.high_peak - sub.low_peak)
            unmixed = np.asarray(fine_by_range)[:, RANGE_EDGES[1:] <= half].sum(axis=1)
            pure = min(int(unmixed[lower].sum()), int(unmixed[keep & ~lower].sum()))
            if pure < min_class_fraction * total:
                stop = (f"{where}: a side of {sub.valley:.4g} is mixed cells ({100 * pure / total:.2f} % of all cells "
                        f"have a local range <= {half:.3g}, half the peak distance)")
                break
        valleys.append(sub.valley)
        best = ThresholdResult(
            sub.valley, best.otsu, True, f"lowest of {len(valleys) + 1} modes separated by valleys",
            low_peak=sub.low_peak, high_peak=sub.high_peak, valley_ratio=sub.valley_ratio,
            low_fraction=below / total, counts=counts, centres=centres,
        )
    best.valleys = [float(v) for v in valleys]
    best.index_step = first_step
    best.stop_reason = stop
    return best
