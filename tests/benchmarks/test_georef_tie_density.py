"""benchmarks/georef_tie_density.py: the dome fit and the block's error at the checkpoints."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "benchmarks"))

import georef_tie_density as td  # noqa: E402


def test_dome_recovers_a_known_quadratic_and_its_range():
    rng = np.random.default_rng(3)
    x, y = rng.uniform(0, 2000, 20000), rng.uniform(0, 1500, 20000)
    u, v = (x - np.median(x)) / 1e3, (y - np.median(y)) / 1e3
    e = 0.1 - 0.3 * u * u - 0.1 * v * v + rng.normal(0, 0.02, x.size)
    d = td.dome(x, y, e, 250.0)
    assert d["dome_centre_m"] == pytest.approx(0.1, abs=0.005)
    assert d["curv_xx_m_km2"] == pytest.approx(-0.3, abs=0.01)
    assert d["curv_yy_m_km2"] == pytest.approx(-0.1, abs=0.01)
    fit = 0.1 - 0.3 * u * u - 0.1 * v * v
    assert d["dome_range_m"] == pytest.approx(np.ptp(fit), abs=0.01)
    assert d["block_median_p5_m"] < d["block_median_p95_m"]


def test_block_error_at_the_checkpoints_is_the_median_of_the_ties_near_each():
    xy = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [2.0, 2.0], [-1.0, 0.0],
                   [100.0, 100.0], [101.0, 100.0], [100.0, 101.0], [99.0, 100.0], [100.0, 99.0]])
    e = np.array([0.1, 0.2, 0.3, 0.4, 0.5, -0.1, -0.2, -0.3, -0.4, -0.5])
    cps = pd.DataFrame({"x": [0.0, 100.0, 500.0], "y": [0.0, 100.0, 500.0]})
    r = td.at_checkpoints(xy, e, cps, 5.0)
    assert r["checkpoints_n"] == 2  # the third has no tie point within 5 m
    assert r["checkpoints_block_mean_m"] == pytest.approx(0.0)
    assert r["checkpoints_block_sd_m"] == pytest.approx(np.std([0.3, -0.3], ddof=1))
