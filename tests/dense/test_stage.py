"""DenseParams: the dense config section of both twin sites builds; a bad key is named."""

from __future__ import annotations

import copy

import pytest

from conftest import REPO
from kitegully import InputError
from kitegully.config import load_yaml
from kitegully.dense import DenseParams

DENSE = load_yaml(REPO / "config/sites/tiny_twin.yaml")["dense"]


def test_site_section_builds():
    p = DenseParams.from_config(DENSE)
    assert p.cell_m == DENSE["cell_m"] and p.matching.levels == DENSE["matching"]["levels"]
    assert p.orthophoto.upsample == DENSE["orthophoto"]["upsample"] and p.shading.azimuth_deg == DENSE["shading"]["azimuth_deg"]


def test_bad_keys_are_named():
    bad = copy.deepcopy(DENSE)
    bad["extent"] = {"xmin": 10.0, "ymin": 0.0, "xmax": 5.0, "ymax": 1.0}
    with pytest.raises(InputError, match=r"dense.extent: xmax/ymax must exceed xmin/ymin"):
        DenseParams.from_config(bad)
    bad = copy.deepcopy(DENSE)
    del bad["orthophoto"]["overlap_m"]
    with pytest.raises(InputError, match=r"dense.orthophoto: missing key 'overlap_m'"):
        DenseParams.from_config(bad)
    bad = copy.deepcopy(DENSE)
    bad["matching"]["window"] = 3
    with pytest.raises(InputError, match=r"dense.matching: unknown key 'window'"):
        DenseParams.from_config(bad)
