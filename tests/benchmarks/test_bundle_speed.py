"""benchmarks/bundle_speed.py: the compiled bundle kernels and the SciPy reference take the same step."""

from __future__ import annotations

import sys
from pathlib import Path

import pandas as pd

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "benchmarks"))

import bundle_speed as bs  # noqa: E402


def test_small_block_same_step_and_a_table(tmp_path):
    out = tmp_path / "speed.csv"
    assert bs.main(["--photos", "12", "--points", "4000", "--iterations", "2", "--out", str(out)]) == 0
    t = pd.read_csv(out).set_index("item")
    assert int(t.loc["photos", "kernels"]) == 12
    assert float(t.loc["step max relative difference", "kernels"]) < 1e-6
    assert float(t.loc["one iteration (normal + 1 step) wall s", "reference (numpy + scipy.sparse)"]) > 0
    assert float(t.loc["mean track length", "kernels"]) > 1.5  # points are seen by several photos


def test_synthetic_block_sizes():
    block, survey = bs.synthetic_block(30, 5000)
    assert 24 <= len(block.rv) <= 36 and len(block.points) == 5000 and survey.shape == (8, 3)
    assert len(block.gcp_obs_image) > 8  # every GCP in more than one photo on average
