"""benchmarks/polygons_depth_sources.py: the error parts sum to the total; a bias has no scatter."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pandas as pd

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "benchmarks"))

import polygons_depth_sources as ds  # noqa: E402


def _table() -> pd.DataFrame:
    rng = np.random.default_rng(1)
    n = 60
    true = rng.uniform(0.5, 2.0, n)
    dtm = true - 0.1  # the method: 0.1 m too shallow on every section (a bias)
    dsm = dtm + 0.05  # plants: 0.05 m too deep everywhere
    kite = dsm + rng.normal(0.0, 0.1, n)  # matching: noise only
    return pd.DataFrame({"member": "a", "shape": np.where(np.arange(n) % 2, "U", "V"), "width_true_m": np.where(np.arange(n) < 40, 3.0, 9.0),
                         "depth_true_m": true, "depth_m": kite, "depth_true_dsm_m": dsm, "depth_true_dtm_m": dtm})


def test_the_parts_sum_to_the_total_error():
    d = ds.split_errors(_table())
    assert np.allclose(d["e_kite_dsm"] + d["e_plants"] + d["e_method_on_true_dtm"], d["e_total"])
    assert set(d["kind"]) == {"U", "V", "wide"}


def test_a_bias_has_no_scatter_and_noise_has():
    s = ds.summarise_parts(ds.split_errors(_table())).set_index("member")
    assert abs(s.loc["a", "e_method_on_true_dtm_med_abs"] - 0.1) < 1e-9 and s.loc["a", "e_method_on_true_dtm_scatter"] < 1e-9
    assert abs(s.loc["a", "e_plants_med_abs"] - 0.05) < 1e-9 and s.loc["a", "e_plants_scatter"] < 1e-9
    assert 0.03 < s.loc["a", "e_kite_dsm_scatter"] < 0.12  # MAD of N(0, 0.1) is 0.067
    assert abs(s.loc["all 1 twins, wide", "e_method_on_true_dtm_median"] + 0.1) < 1e-9
