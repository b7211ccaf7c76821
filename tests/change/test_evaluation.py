"""Moritani's MAE/MRE/b and the detection table on constructed cases."""

import numpy as np
import pytest

from kitegully.change.evaluation import detection_table, moritani_plots


def test_moritani_perfect_and_scaled():
    true = np.zeros((40, 40), np.float32)
    true[:20, :20] = -0.1
    true[20:, 20:] = -0.05
    df, s = moritani_plots(true, true, 1.0, 10.0, 0.02)
    assert s["plots"] == 8 and s["mae_m"] == 0 and s["b"] == pytest.approx(1.0)
    df, s = moritani_plots(1.2 * true, true, 1.0, 10.0, 0.02)
    assert s["b"] == pytest.approx(1.2, rel=1e-5) and s["mre_pct"] == pytest.approx(20.0, rel=1e-5)


def test_detection_counts():
    true = np.array([0.5, -0.5, 0.5, 0.0, 0.0, 0.0], np.float32)
    dod = np.array([0.4, -0.4, -0.3, 0.2, 0.0, 0.01], np.float32)
    sigma = np.full(6, 0.1, np.float32)
    det = {"probabilistic": np.array([True, True, True, True, False, False])}
    row = detection_table(dod, sigma, true, det).iloc[0]
    assert (row.true_change_cells, row.detected, row.missed) == (3, 2, 1)  # wrong sign counts as missed
    assert (row.stable_cells, row.false) == (3, 1)
