"""Kite-scale bare-soil map with NDVI where a NIR orthophoto exists (obia.classification.index)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy import ndimage

from kitegully import InputError
from kitegully.io.raster import GridSpec, read_raster, write_raster
from kitegully.obia.classify import ERODED, GRASS, NODATA
from kitegully.obia.kite import bare_soil_map
from kitegully.obia.scene import ObiaParams, classify_scene

CRS = "EPSG:32756"
CELL = 0.02
N = 160
NDVI_PARAMS = ObiaParams(index="ndvi", water_ndvi_below=0.0)
BAND = NDVI_PARAMS.seed_bandwidth_cells


def _site(tmp_path, seed: int = 7):
    """A strip of rock, senescent plants and sea: the plants have the rock's visible colour
    (ExG cannot tell them apart) but a high NIR (NDVI 0.6); the sea has NDVI < 0.

    Writes float reflectance mosaics (RGB, NIR) and a flat DSM; returns the grid and the
    truth (0 plants, 1 rock, 2 water).
    """
    rng = np.random.default_rng(seed)
    grid = GridSpec(290000.0, 6115000.0, CELL, N, N, CRS)
    rows, cols = np.mgrid[0:N, 0:N]
    truth = np.ones((N, N), np.uint8)
    truth[((rows - 50) ** 2 + (cols - 60) ** 2) <= 30 ** 2] = 0
    truth[((rows - 60) ** 2 + (cols - 130) ** 2) <= 20 ** 2] = 0
    truth[rows >= 120] = 2
    # (R, G, B, NIR) reflectance: rock and dry plants alike in the visible
    spec = {1: (0.21, 0.19, 0.17, 0.25), 0: (0.20, 0.19, 0.16, 0.80), 2: (0.03, 0.05, 0.06, 0.01)}
    bands = np.zeros((4, N, N), np.float32)
    for code, s in spec.items():
        bands[:, truth == code] = np.array(s, np.float32)[:, None]
    light = 1.0 + 0.05 * ndimage.gaussian_filter(rng.standard_normal((N, N)), 10) / 0.03
    bands = bands * light[None] * (1.0 + rng.normal(0, 0.02, bands.shape))
    write_raster(tmp_path / "rgb.tif", bands[:3].astype(np.float32), grid)
    write_raster(tmp_path / "nir.tif", bands[3:].astype(np.float32), grid)
    write_raster(tmp_path / "dsm.tif", np.full((N, N), 1.0, np.float32), grid)
    return grid, truth


def test_ndvi_maps_plants_that_exg_cannot_see_and_masks_the_sea(tmp_path):
    grid, truth = _site(tmp_path)
    thr = bare_soil_map(tmp_path / "rgb.tif", tmp_path / "dsm.tif", tmp_path / "ndvi.tif", NDVI_PARAMS, N,
                        nir_path=tmp_path / "nir.tif")
    cls, out_grid = read_raster(tmp_path / "ndvi.tif")
    assert out_grid == grid
    assert thr.bimodal
    # rock NDVI 0.09, plants 0.6: the valley lies between them, water left out of the histogram
    assert 0.1 < thr.valley < 0.6
    water = truth == 2
    assert thr.water_cells == pytest.approx(water.sum(), rel=0.05)
    assert np.mean(cls[water] == NODATA) > 0.97
    land = ~water & ~ndimage.binary_dilation(water, iterations=3)
    edge = ndimage.binary_dilation(truth == 0, iterations=BAND) & ~ndimage.binary_erosion(truth == 0, iterations=BAND)
    core = land & ~edge
    assert np.all(cls[core & (truth == 0)] == GRASS)
    assert np.all(cls[core & (truth == 1)] == ERODED)
    # ExG of the RGB mosaic alone: plants and rock have one colour, so there is no valley
    exg_params = replace(NDVI_PARAMS, index="exg", water_ndvi_below=None)
    thr_exg = bare_soil_map(tmp_path / "rgb.tif", tmp_path / "dsm.tif", tmp_path / "exg.tif", exg_params, N)
    cls_exg, _ = read_raster(tmp_path / "exg.tif")
    acc_ndvi = np.mean(cls[land] == truth[land])
    acc_exg = np.mean(cls_exg[land] == truth[land])
    assert acc_ndvi > 0.97 and acc_exg < acc_ndvi - 0.1
    # the sea is blue-brightest: the ExG map leaves it unclassified as well
    assert thr_exg.water_cells == pytest.approx(water.sum(), rel=0.05)
    assert np.mean(cls_exg[water] == NODATA) > 0.97


def test_ndvi_without_a_nir_orthophoto_is_one_sentence(tmp_path):
    _site(tmp_path)
    with pytest.raises(InputError, match="index is ndvi but the survey has no NIR orthophoto"):
        bare_soil_map(tmp_path / "rgb.tif", tmp_path / "dsm.tif", tmp_path / "x.tif", NDVI_PARAMS, N)


def test_nir_orthophoto_on_another_grid_is_one_sentence(tmp_path):
    grid, _ = _site(tmp_path)
    shifted = GridSpec(grid.x0 + CELL, grid.y0, CELL, N, N, CRS)
    write_raster(tmp_path / "nir2.tif", np.ones((N, N), np.float32), shifted)
    with pytest.raises(InputError, match=r"nir2.tif: NIR orthophoto grid .* is not the RGB orthophoto's"):
        bare_soil_map(tmp_path / "rgb.tif", tmp_path / "dsm.tif", tmp_path / "x.tif", NDVI_PARAMS, N,
                      nir_path=tmp_path / "nir2.tif")


def _cfg(**classification):
    return {"features": {"slope_window_cells": 5}, "seeds": {"bandwidth_cells": 15},
            "growing": {"position_weight": 0.0, "reference": "mean"}, "exg_blur": {"sigma_cells": 1.0, "radius_cells": 2},
            "threshold": {"bins": 256, "min_class_fraction": 0.01, "max_valley_ratio": 0.9, "unimodal_class": "grass"},
            "classification": {"segment_feature": "blurred", "min_area_m2": 0.0, **classification}}


def test_config_index_defaults_to_exg_and_is_checked():
    assert ObiaParams.from_config(_cfg()).index == "exg"
    p = ObiaParams.from_config(_cfg(index="ndvi", water_ndvi_below=0.0))
    assert p.index == "ndvi" and p.water_ndvi_below == 0.0 and p.index_range == (-1.0, 1.0)
    with pytest.raises(InputError, match=r"obia.classification.index: must be one of \['exg', 'ndvi'\], got 'savi'"):
        ObiaParams.from_config(_cfg(index="savi"))
    with pytest.raises(InputError, match="obia.classification.water_ndvi_below: needs index ndvi"):
        ObiaParams.from_config(_cfg(water_ndvi_below=0.0))


def test_close_range_scenes_refuse_ndvi():
    with pytest.raises(InputError, match="scene_01: the close-range scenes have no NIR band"):
        classify_scene(np.ones((3, 10, 10)), np.zeros((10, 10)), 0.02, NDVI_PARAMS, source="scene_01")
