"""The first split of a histogram with more than two modes (kitegully.obia.threshold.find_thresholds, session 43).

Soil, grass and shrubs give three modes; smoothing until two maxima remain merges grass and shrubs and with
them fills the valley above the narrow soil mode. The held-out twin h26 (dense shrubs, grass greenness 0.55)
lost its whole bare-soil map to that (OA 26.6 %).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from kitegully.obia.threshold import IndexHistogram, find_bare_threshold, find_thresholds, fine_histogram, histogram

RANGE = (-1.0, 2.0)  # the kite histogram's fixed ExG range
EDGES = fine_histogram(np.zeros(1), 256, RANGE)[1]

H26 = Path(__file__).parent / "data" / "h26_histogram.npz"
"""The whole-site histogram of held-out twin h26's kite orthophoto (24 M cells), written in session 43 with
:func:`kitegully.obia.kite.site_histogram` (config/sites/kamech_twin.yaml + config/sites/holdout/h26.yaml): soil
at ExG 0.00 (74 % of the cells), grass at 0.13, shrubs at 0.25."""


def _soil_grass_shrubs(n=400_000, seed=1):
    """Blurred ExG shaped like h26's: narrow soil mode 74 %, grass 17 %, shrubs 7 %, 2 % mixed cells between."""
    rng = np.random.default_rng(seed)
    return np.concatenate([rng.normal(0.0, 0.006, int(0.74 * n)), rng.normal(0.13, 0.008, int(0.17 * n)),
                           rng.normal(0.248, 0.015, int(0.07 * n)), rng.uniform(0.0, 0.25, int(0.02 * n))])


def test_three_modes_give_the_valley_above_the_soil():
    counts, centres = histogram(_soil_grass_shrubs(), 256, RANGE)
    res = find_thresholds(counts, centres, 0.01, 0.9)
    assert res.bimodal and 0.03 < res.valley < 0.11
    assert res.valley_ratio < 0.1 and abs(res.low_fraction - 0.75) < 0.02
    # the two-peak split alone (grass and shrubs merged) is what failed
    assert res.reason.startswith("lowest valley of 3 smoothed peaks") and "too shallow" in res.reason


def test_a_part_below_a_valley_is_not_searched_so():
    # a part below a valley has no mode at its high end (the flank of the one above): no look-back there
    counts, centres = histogram(np.concatenate([_soil_grass_shrubs()[:296_000], np.linspace(0.02, 0.2, 64_000)]), 256, RANGE)
    plain = find_thresholds(counts, centres, 0.01, 0.9, open_high=True)
    assert "smoothed peaks" not in plain.reason


def test_a_large_unimodal_histogram_stays_not_bimodal():
    # millions of cells: the earlier levels' noise maxima must not pass for modes
    rng = np.random.default_rng(4)
    for values in (rng.normal(0.2, 0.05, 4_000_000), rng.gamma(4.0, 0.03, 4_000_000)):
        counts, centres = histogram(values, 256, RANGE)
        res = find_thresholds(counts, centres, 0.01, 0.9)
        assert not res.bimodal and res.valley is None


def test_two_clear_modes_are_split_as_before():
    rng = np.random.default_rng(5)
    counts, centres = histogram(np.concatenate([rng.normal(0.0, 0.01, 300_000), rng.normal(0.25, 0.03, 100_000)]), 256, RANGE)
    res = find_thresholds(counts, centres, 0.01, 0.9)
    assert res.reason == "two peaks separated by a valley" and 0.05 < res.valley < 0.2


def test_h26_site_histogram():
    h = IndexHistogram.load(H26)
    assert h.counts.sum() > 20_000_000
    res = find_bare_threshold(h.counts, EDGES, 256, 0.01, 0.9, fine_steps=h.step_sums, fine_by_range=h.by_range)
    # the valley between soil (0.00) and grass (0.13); before session 43 none, and the map was all grass
    assert res.bimodal and 0.05 < res.valley < 0.11 and res.valleys == [res.valley]
    assert res.reason.startswith("lowest valley of 3 smoothed peaks")
