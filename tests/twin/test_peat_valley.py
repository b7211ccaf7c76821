"""The peat-valley DEM twin (issue 16): a paper-like gully system surveyed as a TLS-like DTM."""

from __future__ import annotations

import numpy as np
import pytest

from kitegully import InputError
from kitegully.config import load_yaml
from kitegully.twin.peat_valley import PeatValleyParams, make_peat_valley


@pytest.fixture(scope="module")
def site(repo_root):
    cfg = load_yaml(repo_root / "config" / "sites" / "peat_valley.yaml")
    return make_peat_valley(PeatValleyParams.from_config(cfg["dem_twin"]), cfg["seed"], cfg["site"]["crs"])


def test_a_gully_system_like_the_papers(site):
    g = site.observed.grid
    assert (g.width, g.height, g.cell) == (800, 480, 0.5)
    # one branching system: a main channel and three tributaries, 3.5-45 m wide, 2.4-6 m deep
    assert len(site.polygons) == 4 and set(site.centrelines["gully_id"]) == {0, 1, 2, 3}
    assert 3.5 <= site.centrelines["width_m"].min() and site.centrelines["width_m"].max() <= 45.0
    assert site.centrelines["depth_max_m"].max() == pytest.approx(6.0, abs=0.05)
    assert 9_000 <= site.polygons["area_m2"].sum() <= 13_000
    # the truth is carved into the DTM: the axis of the main channel lies ~D below its rims
    assert np.nanmax(site.truth.data) - np.nanmin(site.truth.data) > 6.0


def test_tls_like_survey_noise_and_occlusion(site):
    obs, truth = site.observed.data, site.truth.data
    hole = np.isnan(obs)
    assert 0.01 <= hole.mean() <= 0.05  # ~3 % empty cells, left for the stage's moving planes
    assert not np.isnan(truth).any()
    assert np.std(obs[~hole] - truth[~hole]) == pytest.approx(0.034, rel=0.05)


def test_same_seed_same_site_other_seed_other_noise(repo_root, site):
    cfg = load_yaml(repo_root / "config" / "sites" / "peat_valley.yaml")
    p = PeatValleyParams.from_config(cfg["dem_twin"])
    other = make_peat_valley(p, cfg["seed"] + 1, cfg["site"]["crs"])
    assert not np.array_equal(np.isnan(other.observed.data), np.isnan(site.observed.data))


def test_bad_kind_and_extent_are_one_sentence():
    with pytest.raises(InputError, match=r"^dem_twin.kind: must be one of \('peat_valley',\), got 'fjord'$"):
        PeatValleyParams(kind="fjord")
    with pytest.raises(InputError, match=r"^dem_twin.width_m/height_m: the peat valley's gullies need at least 400 x 240 m, got 300.0 x 240.0$"):
        PeatValleyParams(width_m=300.0)
