"""benchmarks/dense_final_window.py: DSM − truth by land cover and the gullies' resolved depth."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "benchmarks"))

from dense_final_window import GULLY, score_box  # noqa: E402

CELL = 0.2


def _site():
    """A grass plane with a 1 m deep, 3 m wide gully and a 1 m deep, 0.6 m wide one (land cover 3 / 9)."""
    x = (np.arange(200) + 0.5) * CELL
    true = np.zeros((100, 200))
    lc = np.full(true.shape, 3, dtype=np.uint8)
    wide = np.abs(x - 10.0) < 1.5
    narrow = np.abs(x - 30.0) < 0.3
    true[:, wide | narrow] = -1.0
    lc[:, wide | narrow] = GULLY
    return true, lc, wide, narrow


def test_a_dsm_equal_to_the_truth_resolves_every_gully():
    true, lc, _, _ = _site()
    row = score_box(true.copy(), true, lc, CELL)
    assert row["open_median_m"] == 0 and row["gully_median_m"] == 0
    assert row["gully_depth_ratio_median"] == 1 and row["narrow_depth_ratio_median"] == 1
    assert row["narrow_depth_cells"] == 100 * 3 and row["valid_pct"] == 100


def test_a_half_filled_narrow_floor_and_a_void():
    true, lc, wide, narrow = _site()
    dsm = true.copy()
    dsm[:, narrow] = -0.5          # the window fills half of the narrow gully's depth
    dsm[:50, :20] = np.nan         # a void on open ground
    row = score_box(dsm, true, lc, CELL)
    assert row["narrow_depth_ratio_median"] == 0.5
    assert row["gully_median_m"] == 0.0  # the wide gully (15 cells across) outnumbers the narrow one (3)
    assert np.isclose(row["valid_pct"], 100 * (1 - 50 * 20 / dsm.size))
    assert row["open_median_m"] == 0 and row["open_nmad_m"] == 0
