"""Similarity estimation: exact recovery, Horn's quaternion method, tape scale, outlier rejection."""

from __future__ import annotations

import numpy as np
import pytest

from kitegully import InputError
from kitegully.georef.geometry import rotvec_to_matrix
from kitegully.georef.similarity import Similarity, horn_quaternion, robust_similarity, tape_horn, tape_scale, umeyama


def _known(seed=0, n=6):
    rng = np.random.default_rng(seed)
    a = rng.uniform(-5, 5, (n, 3))
    sim = Similarity(37.5, rotvec_to_matrix(np.array([[0.3, -1.2, 2.0]]))[0], np.array([340600.0, 548100.0, 70.0]))
    return a, sim.apply(a), sim


def test_umeyama_recovers_a_known_transform_exactly():
    a, b, sim = _known()
    est = umeyama(a, b)
    assert est.scale == pytest.approx(sim.scale, rel=1e-12)
    np.testing.assert_allclose(est.R, sim.R, atol=1e-12)
    np.testing.assert_allclose(est.t, sim.t, atol=1e-6)  # 1e-6 m at 5e5 m coordinates
    np.testing.assert_allclose(est.apply(a), b, atol=1e-6)


def test_horn_quaternion_matches_rotation_on_scaled_points():
    a, b, sim = _known(1)
    rigid = horn_quaternion(a * sim.scale, b)
    np.testing.assert_allclose(rigid.R, sim.R, atol=1e-10)
    np.testing.assert_allclose(rigid.t, sim.t, atol=1e-6)


def test_tape_scale_and_horn_variant_of_paper_004():
    a, b, sim = _known(2, n=3)
    ids = ["P1", "P2", "P3"]
    model = dict(zip(ids, a))
    # taped triangle: true distances; GPS: ±2 m noise
    edges = [(i, j, float(np.linalg.norm(b[k] - b[m]))) for (k, i), (m, j) in [((0, "P1"), (1, "P2")), ((1, "P2"), (2, "P3")), ((0, "P1"), (2, "P3"))]]
    s, ratios = tape_scale(model, edges)
    assert s == pytest.approx(sim.scale, rel=1e-12) and np.ptp(ratios) < 1e-9
    gps = dict(zip(ids, b + np.random.default_rng(5).normal(0, 2.0, b.shape)))
    est = tape_horn(model, gps, edges)
    assert est.scale == pytest.approx(sim.scale, rel=1e-12)  # scale comes from the tape, not the GPS
    # a 2 m GPS error over 3 points moves the centroid by about 2/sqrt(3) m per axis
    assert np.linalg.norm(est.apply(a).mean(0) - b.mean(0)) < 3 * 2.0 * np.sqrt(3) / np.sqrt(3)
    with pytest.raises(InputError, match="taped distance"):
        tape_scale(model, [("P1", "X9", 2.0)])


def test_too_few_or_collinear_points_raise():
    with pytest.raises(InputError, match="at least 3"):
        umeyama(np.zeros((2, 3)), np.zeros((2, 3)))
    line = np.column_stack([np.arange(4.0), np.zeros(4), np.zeros(4)])
    with pytest.raises(InputError, match="collinear"):
        umeyama(line, line)


def test_robust_similarity_drops_one_displaced_point_only():
    a, b, sim = _known(3, n=6)
    noisy = b + np.random.default_rng(4).normal(0, 0.02, b.shape)
    noisy[2] += [3.0, -2.0, 1.0]  # one survey blunder of 3.7 m
    est, inl = robust_similarity(a, noisy, max_residual_m=0.2)
    assert inl.tolist() == [True, True, False, True, True, True]
    assert np.max(np.linalg.norm(est.apply(a[inl]) - noisy[inl], axis=1)) < 5 * 0.02 * np.sqrt(3)
    # without a blunder nothing is dropped
    _, inl2 = robust_similarity(a, b + 0.001, max_residual_m=0.2)
    assert inl2.all()
