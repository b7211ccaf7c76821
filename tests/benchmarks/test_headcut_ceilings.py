"""benchmarks/headcut_ceilings.py: member configs and the per-surface summary."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "benchmarks"))

import headcut_ceilings as hc  # noqa: E402


def test_member_configs_take_their_own_overrides():
    assert hc.site_config("kamech_twin")["seed"] == hc.yaml.safe_load(hc.BASE.read_text())["seed"]
    assert hc.site_config("ens1")["seed"] == 101
    assert hc.site_config("h1")["seed"] == 606
    assert hc.site_config("ens1")["change"] == hc.site_config("kamech_twin")["change"]


def test_summary_counts_and_medians_per_surface_and_pooled():
    rows = []
    for member, errs in (("a", [0.2, -1.0, np.nan]), ("b", [0.4, 3.0, -0.1])):
        for surface in hc.SURFACES:
            for e in errs:
                rows.append(dict(member=member, surface=surface, true_retreat_m=1.0, error_m=e))
            rows.append(dict(member=member, surface=surface, true_retreat_m=0.0, error_m=0.05))
    s = hc.summary(pd.DataFrame(rows)).set_index(["member", "surface"])
    a = s.loc[("a", "photogrammetric")]
    assert a["retreated_matched"] == 3 and a["retreated_measured"] == 2
    assert a["retreated_median_abs_error_m"] == pytest.approx(0.6)
    assert a["stable_measured"] == 1 and a["stable_median_abs_error_m"] == pytest.approx(0.05)
    pooled = s.loc[("all twins (pooled)", "true DTM")]
    assert pooled["retreated_measured"] == 5
    assert pooled["retreated_median_abs_error_m"] == pytest.approx(0.4)
