"""Lowest-mode (bare-soil) threshold, fine histograms and the blue-dominant test (kitegully.obia.threshold, indices)."""

from __future__ import annotations

import numpy as np
import pytest

from kitegully.obia.indices import blue_dominant, excess_green
from kitegully.obia.threshold import (
    DIP_SIGMAS,
    FINE_BINS_PER_BIN,
    _dip_is_significant,
    central_histogram,
    find_bare_threshold,
    find_thresholds,
    fine_histogram,
    histogram,
)

RANGE = (-1.0, 2.0)  # the kite histogram's fixed ExG range


def _dry_site_exg(n=400_000, seed=1, water=0.0):
    """Blurred ExG of a dry site like ens2: soil 65 %, straw 20 %, woody 12 %, mixed edges 3 %.

    Modes as measured on the ensemble orthophotos: soil ExG 0.00 (SD 0.008), straw 0.057
    (SD 0.006), shrubs 0.24 (SD 0.02), and cells mixing straw and shrubs spread between.
    ``water`` adds that share of open-water cells at ExG 0.036 (SD 0.003).
    """
    rng = np.random.default_rng(seed)
    parts = [rng.normal(0.0, 0.008, int(0.65 * n)), rng.normal(0.057, 0.006, int(0.20 * n)),
             rng.normal(0.24, 0.02, int(0.12 * n)), rng.uniform(0.07, 0.22, int(0.03 * n))]
    if water:
        parts.append(rng.normal(0.036, 0.003, int(water * n)))
    return np.concatenate(parts)


def _fine(values):
    return fine_histogram(values, 256, RANGE)


def test_fine_histogram_groups_into_the_plain_histogram():
    v = _dry_site_exg(50_000)
    fine, edges = _fine(v)
    assert fine.size == 256 * FINE_BINS_PER_BIN and edges.size == fine.size + 1
    plain, _ = histogram(v, 256, RANGE)
    grouped = fine.reshape(256, FINE_BINS_PER_BIN).sum(axis=1)
    # identical up to values that sit exactly on a (float-rounded) bin edge
    assert np.abs(grouped - plain).sum() <= 2
    assert fine.sum() == v.size


def test_central_histogram_spans_the_central_cells_and_keeps_every_count():
    v = np.concatenate([_dry_site_exg(100_000), [-0.9, 1.8]])  # two far outliers
    fine, edges = _fine(v)
    counts, centres = central_histogram(fine, edges, 256)
    assert counts.sum() == v.size  # outliers go into the end bins
    assert 128 <= counts.size <= 256
    # the range is that of the data (0.1 % cut each end), not [-1, 2]
    assert centres[0] > -0.05 and centres[-1] < 0.32
    width = centres[1] - centres[0]
    assert width == pytest.approx(round(width / (edges[1] - edges[0])) * (edges[1] - edges[0]))


def test_two_peak_valley_maps_straw_as_bare_lowest_mode_does_not():
    v = _dry_site_exg()
    fine, edges = _fine(v)
    counts, centres = histogram(v, 256, RANGE)
    two = find_thresholds(counts, centres, 0.01, 0.9)
    # the paper's two strongest peaks: soil + straw against shrubs
    assert two.bimodal and two.valley > 0.1
    res = find_bare_threshold(fine, edges, 256, 0.01, 0.9)
    assert res.bimodal
    assert len(res.valleys) == 2 and res.valleys[0] == pytest.approx(two.valley)
    # the last valley lies between soil and straw
    assert 0.015 < res.valley < 0.05
    assert res.low_peak == pytest.approx(0.0, abs=0.006) and res.high_peak == pytest.approx(0.057, abs=0.006)
    assert res.low_fraction == pytest.approx(0.65, abs=0.01)
    # Otsu, counts and centres stay those of the first histogram
    assert res.otsu == two.otsu and np.array_equal(res.counts, counts)


def test_two_cover_types_keep_the_paper_valley():
    rng = np.random.default_rng(4)
    v = np.concatenate([rng.normal(0.0, 0.01, 60_000), rng.normal(0.25, 0.03, 40_000)])
    fine, edges = _fine(v)
    counts, centres = histogram(v, 256, RANGE)
    two = find_thresholds(counts, centres, 0.01, 0.9)
    res = find_bare_threshold(fine, edges, 256, 0.01, 0.9)
    assert res.valleys == [two.valley] and res.valley == two.valley
    assert res.reason == two.reason


def test_noise_bumps_on_a_flat_tail_are_no_mode():
    # soil plus cells that mix soil and grass at patch edges: a long flat tail whose
    # counting noise leaves bumps after smoothing; the 3-sigma dip test rejects them
    rng = np.random.default_rng(5)
    v = np.concatenate([rng.normal(0.0, 0.01, 12_000), rng.uniform(0.02, 0.3, 1_500), rng.normal(0.35, 0.02, 44_000)])
    fine, edges = _fine(v)
    res = find_bare_threshold(fine, edges, 256, 0.01, 0.9)
    assert res.bimodal and len(res.valleys) == 1
    assert 0.05 < res.valley < 0.3


def test_dip_test_counts_poisson_noise():
    centres = np.arange(100) * 0.001
    flat = np.full(100, 1000)
    bump = flat.copy()
    bump[60:70] += 40  # 400 extra cells against 20 000 around: < 3 sigma (424)
    assert not _dip_is_significant(bump, centres, 0.045, 0.065)
    mode = flat.copy()
    mode[60:70] += 200  # 2000 extra: far above 3 sigma
    assert _dip_is_significant(mode, centres, 0.045, 0.065)
    assert DIP_SIGMAS == 3.0


def test_insignificant_bump_on_a_tail_is_not_split_off():
    # 40 cells at ExG 0.15 on a sparse tail: a split without the dip test, none with it
    rng = np.random.default_rng(1)
    v = np.concatenate([rng.normal(0.0, 0.01, 12_000), rng.uniform(0.02, 0.3, 1_500), rng.normal(0.15, 0.01, 40),
                        rng.normal(0.35, 0.02, 44_000)])
    res = find_bare_threshold(*_fine(v), 256, 0.01, 0.9)
    assert len(res.valleys) == 1 and res.valley > 0.2


def test_small_middle_mode_below_min_class_fraction_is_not_split_off():
    rng = np.random.default_rng(6)
    v = np.concatenate([rng.normal(0.0, 0.008, 70_000), rng.normal(0.06, 0.005, 500), rng.normal(0.25, 0.02, 29_500)])
    fine, edges = _fine(v)
    res = find_bare_threshold(fine, edges, 256, 0.01, 0.9)
    assert len(res.valleys) == 1 and res.valley > 0.1


def test_unimodal_histogram_stays_not_bimodal():
    rng = np.random.default_rng(7)
    fine, edges = _fine(rng.normal(0.2, 0.05, 100_000))
    res = find_bare_threshold(fine, edges, 256, 0.01, 0.7)
    assert not res.bimodal and res.valley is None and res.valleys == []


def test_fine_histogram_must_group_evenly():
    fine, edges = _fine(_dry_site_exg(10_000))
    with pytest.raises(ValueError, match="not a multiple"):
        find_bare_threshold(fine[:-1], edges[:-1], 256, 0.01, 0.9)


def test_water_is_a_mode_of_its_own_between_soil_and_straw():
    # why open water is left out of the histogram: on a green site (no straw mode) a 3 %
    # pond at ExG 0.036 becomes a "mode" above soil, and the split moves below it
    rng = np.random.default_rng(8)
    soil = rng.normal(0.0, 0.008, 650_000)
    green = rng.normal(0.15, 0.01, 300_000)
    pond = rng.normal(0.036, 0.003, 40_000)
    with_pond = find_bare_threshold(*_fine(np.concatenate([soil, green, pond])), 256, 0.01, 0.9)
    without = find_bare_threshold(*_fine(np.concatenate([soil, green])), 256, 0.01, 0.9)
    assert len(without.valleys) == 1 and without.valley > 0.05
    assert len(with_pond.valleys) == 2 and with_pond.valley < 0.036


@pytest.mark.parametrize(
    ("rgb", "expected"),
    [
        ((0.04, 0.07, 0.09), True),  # open water: red absorbed
        ((0.46, 0.40, 0.32), False),  # bare soil (iron oxides): R > G > B
        ((0.33, 0.26, 0.20), False),  # ploughed soil
        ((0.36, 0.33, 0.22), False),  # dry straw: G close to R, blue absorbed
        ((0.10, 0.22, 0.07), False),  # green grass
        ((0.07, 0.13, 0.05), False),  # shrub
        ((0.20, 0.22, 0.30), True),  # shade lit by the blue sky
        ((0.50, 0.50, 0.50), False),  # grey: blue not brighter than both
    ],
)
def test_blue_dominant_on_the_twin_palette(rgb, expected):
    r, g, b = (np.array([v], dtype=np.float32) for v in rgb)
    assert bool(blue_dominant(r, g, b)[0]) is expected


def test_straw_lies_between_soil_and_green_in_exg():
    # the physics the lowest-mode rule rests on, on the twin's palette reflectances
    soil, straw, green = ((0.46, 0.40, 0.32), (0.36, 0.33, 0.22), (0.10, 0.22, 0.07))
    e = [float(excess_green(*(np.array([c]) for c in rgb))[0]) for rgb in (soil, straw, green)]
    assert e[0] < 0.03 < e[1] < 0.15 < e[2]
