"""benchmarks/twin_ensemble.py: config merging, member list and the mean/worst rows."""

from __future__ import annotations

import sys
from pathlib import Path

import pandas as pd
import pytest

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "benchmarks"))

import twin_ensemble as te  # noqa: E402


def test_deep_merge_overrides_nested_keys_only():
    a = {"twin": {"texture": {"grass_greenness": 0.6, "x": 1}}, "seed": 1}
    b = {"twin": {"texture": {"grass_greenness": 0.1}}, "seed": 2}
    m = te.deep_merge(a, b)
    assert m == {"twin": {"texture": {"grass_greenness": 0.1, "x": 1}}, "seed": 2}
    assert a["twin"]["texture"]["grass_greenness"] == 0.6


def test_members_are_default_plus_five():
    names = [n for n, _ in te.members(None, te.BASE)]
    assert names[0] == "default" and len(names) == 6
    with pytest.raises(SystemExit, match="unknown ensemble member"):
        te.members(["nope"], te.BASE)


def test_worst_row_takes_the_bad_side_of_each_column():
    df = pd.DataFrame({"member": ["a", "b"], "dig_good_fit_5m_pct": [90.0, 80.0], "dig_false_positive_5m_pct": [5.0, 9.0],
                       "camera_rmse_m": [0.2, 0.3], "checkpoint_mean_m": [0.05, -0.1], "dsm_coverage_pct": [99.0, 95.0]})
    s = te.summarise(df).set_index("member")
    assert s.loc["mean", "dig_good_fit_5m_pct"] == pytest.approx(85.0)
    assert s.loc["worst", "dig_good_fit_5m_pct"] == 80.0
    assert s.loc["worst", "dig_false_positive_5m_pct"] == 9.0
    assert s.loc["worst", "camera_rmse_m"] == 0.3
    assert s.loc["worst", "checkpoint_mean_m"] == -0.1
    assert s.loc["worst", "dsm_coverage_pct"] == 95.0
