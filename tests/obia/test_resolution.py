"""Index resolution and mixed cells in the lowest-mode descent (kitegully.obia.threshold, indices)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy import ndimage

from kitegully.obia.indices import dn_step, excess_green, exg_step, gaussian_blur, local_range, ndvi, ndvi_step
from kitegully.obia.threshold import (
    RANGE_EDGES,
    STEP_UNIT,
    IndexHistogram,
    find_bare_threshold,
    find_thresholds,
    fine_histogram,
)

RANGE = (-1.0, 2.0)
EDGES = fine_histogram(np.zeros(1), 256, RANGE)[1]


@pytest.mark.parametrize("dtype, step", [(np.uint8, 1.0), (np.uint16, 1.0), (np.int16, 1.0), (np.float32, 0.0), ("float64", 0.0)])
def test_dn_step_of_integer_and_float_bands(dtype, step):
    assert dn_step(dtype) == step


def test_exg_step_is_the_largest_one_dn_change():
    rgb = np.array([[170.0], [165.0], [160.0]])  # soil, DN sum 495
    step = exg_step(*rgb)[0]
    assert step == pytest.approx(2.0 / 495.0, rel=0.01)
    e0 = excess_green(*rgb)[0]
    changes = [abs(excess_green(*(rgb + np.eye(3)[i][:, None]))[0] - e0) for i in range(3)]
    assert step == pytest.approx(max(changes), rel=0.01)
    assert exg_step(*rgb, step=0.0)[0] == 0.0


def test_ndvi_step_is_the_largest_one_dn_change():
    nir, red = np.array([120.0]), np.array([40.0])
    v0 = ndvi(nir, red)[0]
    changes = [abs(ndvi(nir + 1, red)[0] - v0), abs(ndvi(nir, red + 1)[0] - v0)]
    assert ndvi_step(nir, red)[0] == pytest.approx(max(changes), rel=0.02)


def test_local_range_marks_edges_and_nodata():
    v = np.zeros((9, 9), np.float32)
    v[:, 5:] = 0.6
    v[0, 0] = np.nan
    r = local_range(v, 3)
    assert r[4, 2] == 0.0 and r[4, 4] == pytest.approx(0.6) and r[4, 5] == pytest.approx(0.6)
    assert np.isinf(r[1, 1]) and np.isnan(r[0, 0])


def test_index_histogram_counts_as_numpy_and_adds_exactly():
    rng = np.random.default_rng(0)
    v = rng.normal(0.1, 0.2, 50_000)
    v[:10] = EDGES[[0, 1, 2, 100, 1000, -1, -2, -3, 5, 7]]  # values on bin edges
    steps = rng.uniform(0.002, 0.01, v.size)
    ranges = rng.uniform(0, 0.5, v.size)
    h = IndexHistogram.of(v, steps, ranges, EDGES)
    assert np.array_equal(h.counts, np.histogram(v, bins=EDGES)[0])
    assert h.by_range.shape == (EDGES.size - 1, RANGE_EDGES.size - 1)
    assert h.step_sums.sum() * STEP_UNIT == pytest.approx(steps.sum(), rel=1e-6)
    a = IndexHistogram.of(v[:20_000], steps[:20_000], ranges[:20_000], EDGES)
    a += IndexHistogram.of(v[20_000:], steps[20_000:], ranges[20_000:], EDGES, quantised=False)
    assert np.array_equal(a.by_range, h.by_range) and np.array_equal(a.step_sums, h.step_sums) and not a.quantised


CORNER = Path(__file__).parent / "data" / "kamech_corner_histogram.npz"
"""The whole-site histogram of a 600 x 400 m corner of the full-size Kamech twin (GSD 9.6 cm, 21.8 M cells),
written by ``benchmarks/obia_descent.py --save-histogram`` in session 42 (config/sites/kamech_full.yaml,
--cut 600x400 --tile-m 200): its ploughed soil read as two modes 0.0066 apart, and the map fell to OA 45 %."""


def _corner_thresholds():
    h = IndexHistogram.load(CORNER)
    args = (h.counts, EDGES, 256, 0.01, 0.9)
    return h, find_bare_threshold(*args), find_bare_threshold(*args, fine_steps=h.step_sums, fine_by_range=h.by_range)


def test_corner_soil_is_not_split_between_its_one_dn_values():
    h, plain, stage = _corner_thresholds()
    assert h.quantised and h.counts.sum() == 21_840_416
    # without the floor the ploughed soil splits just below ExG 0 (session 41's failure) ...
    assert len(plain.valleys) == 2 and -0.01 < plain.valley < 0.005
    # ... with it the paper's valley between soil and vegetation stands
    assert stage.valleys == [plain.valleys[0]] and 0.05 < stage.valley < 0.12
    assert 0.003 < stage.index_step < 0.005  # about 2 / DN sum of the soil (~500)
    assert "not bimodal" in stage.stop_reason


def _soil_edge_bump_grass(n=200_000, seed=3, bump_range=0.3):
    """Soil (0.0), grass (0.4) and 2 % cells in a bump at 0.15 with local range ``bump_range``."""
    rng = np.random.default_rng(seed)
    soil = rng.normal(0.0, 0.01, int(0.68 * n))
    grass = rng.normal(0.4, 0.03, int(0.30 * n))
    bump = rng.normal(0.15, 0.01, int(0.02 * n))
    values = np.concatenate([soil, grass, bump])
    ranges = np.concatenate([np.full(soil.size, 0.005), np.full(grass.size, 0.01), np.full(bump.size, bump_range)])
    return values, ranges


@pytest.mark.parametrize("bump_range, splits", [(0.3, 1), (0.01, 2)])
def test_a_bump_of_mixed_cells_is_no_cover_a_bump_of_unmixed_cells_is(bump_range, splits):
    values, ranges = _soil_edge_bump_grass(bump_range=bump_range)
    h = IndexHistogram.of(values, np.zeros(values.size), ranges, EDGES)
    assert len(find_bare_threshold(h.counts, EDGES, 256, 0.01, 0.9).valleys) == 2
    thr = find_bare_threshold(h.counts, EDGES, 256, 0.01, 0.9, fine_by_range=h.by_range)
    assert len(thr.valleys) == splits
    if splits == 1:
        assert "mixed cells" in thr.stop_reason


def test_blurred_boundaries_make_mixed_cells_only():
    # a sharp soil / grass boundary, blurred as the stage blurs: the cells between the two
    # colours all have a local range above half the soil-grass distance
    img = np.where(np.arange(60)[None, :] < 30, 0.0, 0.6).repeat(60, axis=0).astype(np.float32)
    blur = gaussian_blur(img, 1.0, 2)
    between = (blur > 0.05) & (blur < 0.55)
    assert between.any() and np.all(local_range(blur, 3)[between] > 0.3)


def test_open_high_end_is_not_a_peak():
    # one mode and the rising flank of the mode above the previous valley
    x = np.linspace(-0.05, 0.3, 120)
    counts = np.rint(5000 * np.exp(-0.5 * (x / 0.01) ** 2) + 400 * np.exp((x - 0.3) / 0.03)).astype(np.int64)
    assert find_thresholds(counts, x, 0.01, 0.9).bimodal
    assert not find_thresholds(counts, x, 0.01, 0.9, open_high=True).bimodal


def test_twin_like_straw_survives_both_tests():
    rng = np.random.default_rng(4)
    n = 300_000
    soil = 0.004 * np.round(rng.normal(0.0, 0.008, int(0.65 * n)) / 0.004)
    straw = rng.normal(0.057, 0.006, int(0.2 * n))
    shrubs = rng.normal(0.24, 0.02, int(0.15 * n))
    values = np.concatenate([soil, straw, shrubs])
    ranges = ndimage.uniform_filter1d(rng.uniform(0.001, 0.01, values.size), 3)
    h = IndexHistogram.of(values, np.full(values.size, 0.004), ranges, EDGES)
    thr = find_bare_threshold(h.counts, EDGES, 256, 0.01, 0.9, fine_steps=h.step_sums, fine_by_range=h.by_range)
    assert len(thr.valleys) == 2 and 0.02 < thr.valley < 0.045
