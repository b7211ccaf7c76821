"""benchmarks/gully_miss_analysis.py: where unmapped traced cells lie on their paths."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "benchmarks"))

from gully_miss_analysis import unmapped_position  # noqa: E402


def test_head_reach_gap_and_tail_on_a_confluence():
    # path A: 0 -> 1 -> 2 -> 3 -> 4 (outlet); path B: 5 -> 6 joins A at 2
    pos_down = np.array([1, 2, 3, 4, -1, 6, 2])
    kept = np.array([0, 1, 0, 1, 0, 0, 0], dtype=bool)
    where = unmapped_position(np.arange(7), pos_down, kept)
    assert list(where) == ["head reach", "mapped", "gap", "mapped", "tail", "head reach", "head reach"]


def test_a_path_with_no_mapped_cell_is_never_mapped():
    pos_down = np.array([1, 2, -1, 4, -1])
    kept = np.array([0, 0, 0, 1, 0], dtype=bool)
    where = unmapped_position(np.arange(5), pos_down, kept)
    assert list(where) == ["never mapped"] * 3 + ["mapped", "tail"]
