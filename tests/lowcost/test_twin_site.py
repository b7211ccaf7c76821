"""The paper-004 twin's spectral bookkeeping, target layout and config checks."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from kitegully import InputError
from kitegully.config import load_yaml
from kitegully.lowcost import spectral as sp
from kitegully.lowcost.twin_site import BANDS, LowcostTwinParams, camera_weights, class_table, target_layout

SITE = "config/sites/lowcost_twin.yaml"


@pytest.fixture(scope="module")
def twin_cfg():
    from pathlib import Path
    return load_yaml(Path(__file__).resolve().parents[2] / SITE)["lowcost"]["twin"]


def test_cameras_see_the_right_bands():
    w = np.arange(400.0, 901.0, 5.0)
    W = camera_weights(w, sp.illuminant("D65", w))
    nir_red = W["nir"][0] / W["nir"][0].sum()
    rgb = W["rgb"] / W["rgb"].sum(axis=1, keepdims=True)
    assert nir_red[BANDS.index("NIR")] > 0.9                 # the converted camera's red channel sees NIR
    assert rgb[0, BANDS.index("NIR")] < 0.05                # the RGB camera's IR-cut filter blocks it
    assert rgb[2, BANDS.index("B")] == rgb[2].max()          # blue channel sees the blue band most


def test_class_ndvi_is_distinct_per_cover(twin_cfg):
    w = np.arange(400.0, 901.0, 5.0)
    t = class_table(twin_cfg["classes"], camera_weights(w, sp.illuminant("D65", w))).set_index("class")
    assert t.loc["water", "ndvi_camera"] < -0.3
    assert abs(t.loc["rock", "ndvi_camera"]) < 0.15
    assert t.loc["plants", "ndvi_camera"] > t.loc["algae", "ndvi_camera"] > 0.4


def test_triads_have_the_taped_side(twin_cfg):
    p = LowcostTwinParams.from_config(twin_cfg)
    xy = target_layout(p, 2013)
    assert len(xy) == 9
    for i in range(1, 4):
        a, b, c = (xy[f"T{i}{k}"] for k in "abc")
        for u, v in ((a, b), (b, c), (c, a)):
            assert np.linalg.norm(u - v) == pytest.approx(2.0, abs=1e-9)


def test_missing_cover_class_is_one_sentence(twin_cfg):
    bad = yaml.safe_load(yaml.safe_dump(twin_cfg))
    del bad["classes"]["water"]
    with pytest.raises(InputError, match="lowcost.twin.classes: cover class 'water' is missing"):
        LowcostTwinParams.from_config(bad)
