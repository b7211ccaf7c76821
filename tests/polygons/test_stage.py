"""Whole chain: parameters from the config, bad input in one sentence."""

from __future__ import annotations

import numpy as np
import pytest

from kitegully import InputError
from kitegully.config import load_yaml
from kitegully.io.raster import GridSpec
from kitegully.polygons.stage import PolygonParams, measure_polygons

from .polygon_synthetic import CRS


def test_params_from_the_site_config(repo_root):
    cfg = load_yaml(repo_root / "config" / "sites" / "kamech_twin.yaml")["polygons"]
    p = PolygonParams.from_config(cfg)
    assert p.cell_m == 0.5 and p.window_cells == 9 and p.thresholds_m == (0.5, 1.0, 1.5, 2.0, 2.5, 3.0)
    assert p.thalweg_follow_flow is True and p.thalweg_incision_ground_m == 6.5  # session 34, pre-registered, adopted
    assert PolygonParams().thalweg_follow_flow is False and PolygonParams().thalweg_incision_ground_m is None
    q = PolygonParams.from_config({**cfg, "thalweg": {k: v for k, v in cfg["thalweg"].items() if k not in ("follow_flow", "incision_ground_m")}})
    assert q.thalweg_follow_flow is False and q.thalweg_incision_ground_m is None  # keys left out: the stage as before
    assert p.ground_along_axis is True and PolygonParams().ground_along_axis is False  # session 35, pre-registered, adopted
    r = PolygonParams.from_config({**cfg, "morphometry": {k: v for k, v in cfg["morphometry"].items() if k != "ground_along_axis"}})
    assert r.ground_along_axis is False  # left out: sections opened across the gully only, as before
    with pytest.raises(InputError, match="^polygons.breaklines.curvature: must be one of"):
        PolygonParams.from_config({**cfg, "breaklines": {**cfg["breaklines"], "curvature": "gaussian"}})


def test_no_thalweg_is_one_clear_sentence():
    grid = GridSpec(0.0, 100.0, 0.5, 100, 100, CRS)
    r, c = np.mgrid[0:100, 0:100]
    z = (10.0 + 0.3 * c).astype(np.float32)  # a steep plane: flow never converges
    with pytest.raises(InputError, match=r"^polygons.thalweg.tci_threshold: no thalweg found: no cells with TCI > 9.0 form a line of at least 10.0 m$"):
        measure_polygons(z, grid, PolygonParams())


def test_dem_too_coarse_is_one_clear_sentence():
    grid = GridSpec(0.0, 100.0, 2.0, 50, 50, CRS)
    z = np.zeros((50, 50), np.float32)
    with pytest.raises(InputError, match=r"^dsm.tif: cell 2.0 m is coarser than polygons.cell_m 0.5 m$"):
        measure_polygons(z, grid, PolygonParams(), dem_name="dsm.tif")


def test_dem_too_small_for_the_window_is_one_clear_sentence():
    grid = GridSpec(0.0, 100.0, 0.5, 12, 12, CRS)
    z = np.zeros((12, 12), np.float32)
    with pytest.raises(InputError, match=r"too small for the 9 x 9 curvature window \(4.5 m\); it needs at least 18 cells a side$"):
        measure_polygons(z, grid, PolygonParams(), dem_name="dsm.tif")
