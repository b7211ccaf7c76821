"""Head scores: precision, recall, median distance (evaluate/heads.py)."""

import numpy as np
import pytest

from kitegully.evaluate.heads import score_heads


def test_one_to_one_matching_within_tolerance():
    true = np.array([[0, 0], [100, 0], [200, 0]], float)
    det = np.array([[3, 4], [1, 0], [100, 10], [500, 500]], float)  # two near head 1, one 10 m off head 2, one false
    s = score_heads(det, true, 15.0)
    assert s["matched"] == 2
    assert s["precision"] == pytest.approx(0.5)
    assert s["recall"] == pytest.approx(2 / 3)
    assert s["median_distance_m"] == pytest.approx(5.5)  # distances 1 and 10
    assert np.isnan(score_heads(np.zeros((0, 2)), true, 15.0)["precision"])
    assert score_heads(np.zeros((0, 2)), true, 15.0)["recall"] == 0.0
