"""benchmarks/polygons_depth_bounds.py: section kinds, the by-kind table and the bias-removal bounds."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pandas as pd

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "benchmarks"))

import polygons_depth_bounds as db  # noqa: E402


def _sections(seed: int = 0) -> pd.DataFrame:
    """Two twins; U unbiased, V 0.2 m too shallow, wide 0.3 m too deep, each with ±0.05 m scatter."""
    rng = np.random.default_rng(seed)
    rows = []
    for member in ("a", "b"):
        for shape, width, bias in (("U", 3.0, 0.0), ("V", 3.0, -0.2), ("U", 10.0, 0.3)):
            for e in bias + rng.uniform(-0.05, 0.05, 40):
                rows.append({"member": member, "shape": shape, "width_true_m": width, "depth_error_m": e})
    d = pd.DataFrame(rows)
    d["kind"] = db.section_kinds(d, 6.0)
    return d


def test_wide_sections_are_their_own_kind_whatever_their_shape():
    d = _sections()
    assert set(d.loc[d["width_true_m"] > 6, "kind"]) == {"wide"}
    assert set(d.loc[d["width_true_m"] <= 6, "kind"]) == {"U", "V"}


def test_by_kind_gives_each_twin_and_the_pooled_medians():
    t = db.by_kind(_sections()).set_index(["member", "kind"])
    assert abs(t.loc[("a", "V"), "median_error_m"] + 0.2) < 0.02
    assert abs(t.loc[("all 2 twins", "wide"), "median_error_m"] - 0.3) < 0.02
    assert t.loc[("all 2 twins", "U"), "sections"] == 80


def test_removing_the_biases_leaves_only_the_scatter():
    b = db.bias_bounds(_sections()).set_index(["bias removed", "medians"])
    measured = b.loc[("none (as measured)", "pooled")]
    assert measured["worst_m"] > 0.15 and measured["twins_at_or_below_0.15_m"] == 0
    removed = b.loc[("U + V + wide", "pooled")]
    assert removed["worst_m"] < 0.05 and removed["twins_at_or_below_0.15_m"] == 2  # scatter is ±0.05 m
    assert b.loc[("V", "pooled"), "mean_m"] < measured["mean_m"]
