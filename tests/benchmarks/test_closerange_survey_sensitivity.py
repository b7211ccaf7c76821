"""benchmarks/closerange_survey_sensitivity.py: re-drawn sphere surveys on a constructed model."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "benchmarks"))

import closerange_survey_sensitivity as cs  # noqa: E402

SPHERES = np.array([[0.0, 0.0, 0.0], [6.0, 0.5, 0.3], [5.5, 6.0, 0.6], [-0.5, 5.5, 0.2]])


def test_a_perfect_survey_leaves_the_run_as_it_was():
    m, s = cs.scene_draws(SPHERES, np.array([1.01, 0.99]), 0.0, 0.0, 5, np.random.default_rng(0))
    assert np.allclose(m, 0.0, atol=1e-12) and np.allclose(s, 1.0)


def test_marker_error_grows_with_the_survey_and_no_rule_gives_nan():
    rng = np.random.default_rng(1)
    m1, s1 = cs.scene_draws(SPHERES, np.array([1.0, 1.0]), 0.015, 0.015, 400, rng)
    m10, _ = cs.scene_draws(SPHERES, np.zeros(0), 0.10, 0.10, 400, rng)
    # 4 points, 7 parameters: residuals are about sqrt(5/12) of the survey error per coordinate
    assert 0.6 * 0.015 < np.median(m1) < 1.6 * 0.015 and 0.6 * 0.10 < np.median(m10) < 1.6 * 0.10
    assert np.median(s1) < 1.0  # 1.5 cm over a 6 m square: a few tenths of a per cent of scale
    _, s = cs.scene_draws(SPHERES, np.zeros(0), 0.015, 0.015, 3, rng)
    assert np.isnan(s).all()
