"""ObiaParams.from_config (kitegully.obia.scene): built from the obia: method sub-sections, keys checked."""

from __future__ import annotations

import copy
from pathlib import Path

import pytest

from kitegully import InputError
from kitegully.config import load_yaml
from kitegully.obia.scene import ObiaParams

SITES = Path(__file__).resolve().parents[2] / "config" / "sites"


@pytest.mark.parametrize("site", ["tiny_twin", "kamech_twin", "boruszyn_kap"])
def test_obia_params_from_each_site(site):
    obia = load_yaml(SITES / f"{site}.yaml")["obia"]
    p = ObiaParams.from_config(obia)
    assert p.seed_bandwidth_cells == int(obia["seeds"]["bandwidth_cells"])
    assert p.min_area_m2 == float(obia["classification"]["min_area_m2"])


def test_obia_params_name_a_missing_or_unknown_key():
    obia = load_yaml(SITES / "tiny_twin.yaml")["obia"]
    bad = copy.deepcopy(obia)
    del bad["exg_blur"]["radius_cells"]
    with pytest.raises(InputError, match="obia.exg_blur: missing key 'radius_cells'"):
        ObiaParams.from_config(bad)
    bad = copy.deepcopy(obia)
    bad["seeds"]["bandwith_cells"] = 15
    with pytest.raises(InputError, match="obia.seeds: unknown key 'bandwith_cells'"):
        ObiaParams.from_config(bad)
    with pytest.raises(InputError, match="obia: missing key 'threshold'"):
        ObiaParams.from_config({k: v for k, v in obia.items() if k != "threshold"})
