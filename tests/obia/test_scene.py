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


def test_scene_rasters_are_read_on_one_grid(tmp_path):
    import numpy as np

    from kitegully.io.raster import GridSpec, write_raster
    from kitegully.obia.scene import read_scene_rasters

    g = GridSpec(545000.0, 4090000.0, 0.02, 30, 20, "EPSG:32632")
    rgb = np.random.default_rng(0).integers(0, 255, (3, 20, 30)).astype(np.uint8)
    write_raster(tmp_path / "o.tif", rgb, g, nodata=None)
    write_raster(tmp_path / "d.tif", np.full((20, 30), 100.0, np.float32), g)
    write_raster(tmp_path / "m.tif", np.ones((20, 30), np.uint8), g, nodata=None)
    o, d, grid, (m,) = read_scene_rasters(tmp_path / "o.tif", tmp_path / "d.tif", tmp_path / "m.tif")
    assert o.dtype == np.uint8 and np.array_equal(o, rgb) and d.dtype == np.float32 and m.sum() == 600
    g2 = GridSpec(545000.0, 4090000.0, 0.02, 31, 20, "EPSG:32632")
    write_raster(tmp_path / "m2.tif", np.ones((20, 31), np.uint8), g2, nodata=None)
    with pytest.raises(InputError, match=r"m2\.tif: its grid differs from the scene orthophoto"):
        read_scene_rasters(tmp_path / "o.tif", tmp_path / "d.tif", tmp_path / "m2.tif")
