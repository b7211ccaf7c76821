"""Unit tests of the OBIA bare-soil chain (kitegully.obia)."""

from __future__ import annotations

import numpy as np
import pytest

from kitegully import InputError
from kitegully.obia.accuracy import accuracies, accuracy_rows, area_error, confusion_matrix
from kitegully.obia.classify import ERODED, GRASS, classify_segments, remove_small_eroded, segment_means
from kitegully.obia.features import normalise_features
from kitegully.obia.indices import excess_green, gaussian_blur, ndvi
from kitegully.obia.scene import ObiaParams, classify_scene
from kitegully.obia.seeds import generate_seeds
from kitegully.obia.slope import wood_slope
from kitegully.obia.srg import seeded_region_growing
from kitegully.obia.threshold import find_thresholds, histogram


# --- indices -------------------------------------------------------------------------
@pytest.mark.parametrize(
    "rgb, expected",
    [
        ((0, 255, 0), 2.0),  # pure green: g = 1
        ((255, 0, 0), -1.0),  # pure red
        ((0, 0, 255), -1.0),  # pure blue
        ((128, 128, 128), 0.0),  # any grey: r = g = b = 1/3
        ((50, 100, 50), 0.5),  # g = 0.5, r = b = 0.25
        ((0, 0, 0), 0.0),  # black: defined as 0
    ],
)
def test_excess_green_known_colours(rgb, expected):
    r, g, b = (np.full((2, 2), v, dtype=np.uint8) for v in rgb)
    assert np.allclose(excess_green(r, g, b), expected, atol=1e-6)


def test_excess_green_is_scale_invariant_and_3g_minus_1():
    rng = np.random.default_rng(0)
    rgb = rng.uniform(1, 255, (3, 20, 20))
    e = excess_green(*rgb)
    assert np.allclose(e, excess_green(*(rgb * 0.37)), atol=1e-5)
    assert np.allclose(e, 3 * rgb[1] / rgb.sum(axis=0) - 1, atol=1e-5)


def test_ndvi_values():
    assert np.allclose(ndvi(np.array([0.5, 0.1, 0.0]), np.array([0.1, 0.1, 0.0])), [4 / 6, 0.0, 0.0])


def test_gaussian_blur_keeps_constant_and_nan():
    v = np.full((9, 9), 0.3, dtype=np.float32)
    v[4, 4] = np.nan
    out = gaussian_blur(v, 1.0, 2)
    assert np.isnan(out[4, 4])
    assert np.allclose(out[np.isfinite(out)], 0.3, atol=1e-6)


# --- slope ---------------------------------------------------------------------------
def test_wood_slope_plane_and_quadratic():
    cell = 0.02
    n = 41
    y, x = np.mgrid[0:n, 0:n] * cell
    plane = 0.7 * x + 0.2 * y  # rows go south: gradient magnitude is what matters
    assert np.allclose(wood_slope(plane, cell), np.degrees(np.arctan(np.hypot(0.7, 0.2))), atol=1e-4)
    # the quadratic terms must not bias the gradient at the window centre
    c = n // 2
    quad = 3.0 * (x - x[c, c]) ** 2 + 2.0 * (y - y[c, c]) ** 2 + 0.5 * (x - x[c, c])
    assert wood_slope(quad, cell)[c, c] == pytest.approx(np.degrees(np.arctan(0.5)), abs=1e-3)


# --- threshold -----------------------------------------------------------------------
def _mixture(n_small, n_large, seed=1):
    rng = np.random.default_rng(seed)
    return np.concatenate([rng.normal(0.0, 0.03, n_small), rng.normal(0.3, 0.05, n_large)])


def test_valley_on_bimodal_histogram_with_unequal_classes():
    values = _mixture(5_000, 95_000)
    counts, centres = histogram(values, 256)
    res = find_thresholds(counts, centres, min_class_fraction=0.01, max_valley_ratio=0.7)
    assert res.bimodal and res.valley is not None
    # density minimum of the mixture, found on a fine grid
    grid = np.linspace(0.0, 0.3, 30001)
    pdf = 0.05 / 0.03 * np.exp(-0.5 * (grid / 0.03) ** 2) + 0.95 / 0.05 * np.exp(-0.5 * ((grid - 0.3) / 0.05) ** 2)
    true_min = grid[np.argmin(pdf)]
    width = centres[1] - centres[0]
    # smoothing the histogram moves the valley by a few bins at most
    assert abs(res.valley - true_min) < 5 * width
    # Otsu drifts towards the larger class (higher values)
    assert res.otsu > res.valley + 5 * width
    below = np.mean(values <= res.valley)
    assert below == pytest.approx(0.05, abs=0.01)


def test_unimodal_histogram_is_reported_not_forced():
    rng = np.random.default_rng(2)
    counts, centres = histogram(rng.normal(0.2, 0.05, 100_000), 256)
    res = find_thresholds(counts, centres, min_class_fraction=0.01, max_valley_ratio=0.7)
    assert not res.bimodal
    assert res.valley is None
    assert res.otsu is not None  # Otsu always splits; that is the point of the check
    assert res.reason


def test_tiny_second_mode_below_min_fraction_is_not_bimodal():
    counts, centres = histogram(_mixture(300, 99_700), 256)
    res = find_thresholds(counts, centres, min_class_fraction=0.01, max_valley_ratio=0.7)
    assert not res.bimodal and res.valley is None


def test_a_few_outlying_cells_do_not_make_a_peak():
    # A kite orthophoto's ExG has rare outliers (dark shadows, saturated roofs) far from
    # the data; the histogram spans the fixed ExG range, so those isolated counts used to
    # survive the smoothing as a "peak" and hide the real valley.
    rng = np.random.default_rng(3)
    values = np.concatenate([_mixture(30_000, 70_000), rng.uniform(-0.45, -0.35, 20), rng.uniform(0.6, 0.7, 10)])
    edges = np.linspace(-1.0, 2.0, 257)
    counts = np.histogram(values, bins=edges)[0]
    centres = 0.5 * (edges[:-1] + edges[1:])
    res = find_thresholds(counts, centres, min_class_fraction=0.01, max_valley_ratio=0.7)
    assert res.bimodal, res.reason
    assert res.low_peak == pytest.approx(0.0, abs=0.03) and res.high_peak == pytest.approx(0.3, abs=0.03)
    assert 0.05 < res.valley < 0.2
    assert res.low_fraction == pytest.approx(0.30, abs=0.02)


# --- region growing ------------------------------------------------------------------
def _pieces(n=60):
    r, c = np.mgrid[0:n, 0:n]
    truth = np.where(c < n // 2, 1, 2) + np.where(r < n // 2, 0, 2)
    truth[(r - 40) ** 2 + (c - 40) ** 2 < 80] = 5
    return truth


def test_region_growing_recovers_piecewise_constant_image():
    truth = _pieces()
    rng = np.random.default_rng(3)
    levels = {1: (0.0, 0.0), 2: (1.0, 0.0), 3: (0.0, 1.0), 4: (1.0, 1.0), 5: (0.5, 2.0)}
    feats = np.stack([np.vectorize(lambda t, k=k: levels[t][k])(truth) for k in range(2)], axis=-1)
    feats = feats + rng.normal(0, 0.05, feats.shape)  # noise << steps (>= 0.5)
    seeds = np.zeros(truth.shape, dtype=np.int32)
    for lab in levels:
        rr, cc = np.argwhere(truth == lab)[len(np.argwhere(truth == lab)) // 2]
        seeds[rr, cc] = lab
    labels, n = seeded_region_growing(feats.astype(np.float32), seeds)
    assert n == 5
    assert np.array_equal(labels, truth)


def test_region_growing_with_generated_seeds_gives_pure_segments():
    truth = _pieces(90)
    rng = np.random.default_rng(4)
    feats = normalise_features([truth.astype(float) + rng.normal(0, 0.05, truth.shape), (truth % 2).astype(float)])
    valid = np.ones(truth.shape, dtype=bool)
    seeds = generate_seeds(feats, valid, 15)
    labels, n = seeded_region_growing(feats, seeds, valid)
    assert labels.min() >= 1 and n >= 5
    # every segment lies inside one piece
    for lab in range(1, n + 1):
        assert len(np.unique(truth[labels == lab])) == 1


def test_region_growing_respects_mask_and_labels_unreached_pieces():
    feats = np.zeros((10, 10, 1), dtype=np.float32)
    valid = np.ones((10, 10), dtype=bool)
    valid[:, 5] = False  # wall: the right half has no seed
    seeds = np.zeros((10, 10), dtype=np.int32)
    seeds[2, 2] = 1
    labels, n = seeded_region_growing(feats, seeds, valid)
    assert n == 2
    assert np.all(labels[:, 5] == 0)
    assert np.all(labels[:, :5] == 1) and np.all(labels[:, 6:] == 2)


# --- classification and accuracy -----------------------------------------------------
def test_segment_means_and_classification():
    segments = np.array([[1, 1, 2], [3, 3, 2]])
    values = np.array([[0.1, 0.3, -0.1], [0.5, np.nan, 0.0]])
    means = segment_means(values, segments, 3)
    assert np.allclose(means[1:], [0.2, -0.05, 0.5])
    cls = classify_segments(means, segments, 0.1)
    assert np.array_equal(cls, [[GRASS, GRASS, ERODED], [GRASS, GRASS, ERODED]])
    assert np.all(classify_segments(means, segments, None, GRASS) == GRASS)


def test_remove_small_eroded():
    cls = np.zeros((10, 10), dtype=np.uint8)
    cls[1:3, 1:3] = ERODED  # 4 cells = 0.04 m^2 at 0.1 m
    cls[5:10, 5:10] = ERODED  # 25 cells = 0.25 m^2
    out = remove_small_eroded(cls, 0.1, 0.1)
    assert out[1:3, 1:3].max() == GRASS and out[5:10, 5:10].min() == ERODED


def test_accuracy_on_hand_made_confusion_matrix():
    # rows = mapped (grass, eroded), columns = reference (grass, eroded)
    conf = np.array([[40, 10], [5, 45]])
    acc = accuracies(conf)
    assert acc["users"] == pytest.approx([40 / 50, 45 / 50])
    assert acc["producers"] == pytest.approx([40 / 45, 45 / 55])
    assert acc["overall"] == pytest.approx(0.85)
    mapped = np.repeat([0, 0, 1, 1], [40, 10, 5, 45])
    reference = np.repeat([0, 1, 0, 1], [40, 10, 5, 45])
    assert np.array_equal(confusion_matrix(mapped, reference), conf)
    rows = accuracy_rows("s1", conf)
    assert rows[1]["class"] == "eroded" and rows[1]["users_accuracy"] == pytest.approx(90.0)
    assert area_error(37.7, 31.8) == pytest.approx((18.553, 5.9), abs=1e-3)  # 001 Table 2, scene 5
    assert np.isnan(area_error(1.0, 0.0)[0])


def test_confusion_ignores_nodata():
    mapped = np.array([0, 1, 255, 1])
    reference = np.array([0, 1, 1, 255])
    assert confusion_matrix(mapped, reference).sum() == 2


def test_confusion_in_chunks_equals_all_at_once_and_stays_small():
    import tracemalloc

    rng = np.random.default_rng(3)
    mapped = rng.choice(np.array([0, 1, 255], dtype=np.uint8), size=(1000, 3001))
    reference = rng.choice(np.array([0, 1, 255], dtype=np.uint8), size=(1000, 3001))
    valid = rng.random((1000, 3001)) > 0.1
    whole = confusion_matrix(mapped, reference, valid=valid, chunk_cells=mapped.size)
    tracemalloc.start()
    chunked = confusion_matrix(mapped, reference, valid=valid, chunk_cells=65_537)  # chunks end mid-row
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert np.array_equal(chunked, whole) and whole.sum() > 0
    # int64 codes of the 3 M cells at once would take 24 MB each; a chunk's work arrays < 3 MB
    assert peak < 4e6


def test_classify_scene_rejects_bad_input():
    with pytest.raises(InputError, match="same grid"):
        classify_scene(np.zeros((3, 10, 10)), np.zeros((9, 10)), 0.02, ObiaParams(), source="ortho.tif")
    with pytest.raises(InputError, match="no valid cells"):
        classify_scene(np.zeros((3, 10, 10)), np.full((10, 10), np.nan), 0.02, ObiaParams(), source="ortho.tif")


def test_region_growing_seed_reference_splits_at_equal_seed_distance():
    # SAGA's rule: each cell joins the seed whose own features are nearest, so on a
    # monotone profile f = x^2 with seeds at f = 0 and f = 1 the border is at f = 0.5
    n = 201
    x = np.linspace(0.0, 1.0, n)
    f = np.tile(x ** 2, (3, 1))[..., None].astype(np.float32)
    seeds = np.zeros((3, n), dtype=np.int32)
    seeds[1, 0], seeds[1, -1] = 1, 2
    lab, _ = seeded_region_growing(f, seeds, reference="seed")
    border = np.flatnonzero(lab[1] == 2)[0]
    assert abs(border - np.searchsorted(x ** 2, 0.5)) <= 1
    # the running-mean rule (Adams & Bischof) compares with the growing regions' means,
    # which drift towards the border, so the border moves
    lab_mean, _ = seeded_region_growing(f, seeds, reference="mean")
    assert np.flatnonzero(lab_mean[1] == 2)[0] != border
    with pytest.raises(ValueError):
        seeded_region_growing(f, seeds, reference="median")
