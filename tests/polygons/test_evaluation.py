"""Evaluation: Table 1 statistics, operators reproducible, scores against truth."""

from __future__ import annotations

import geopandas as gpd
import numpy as np
import pandas as pd
import pytest
import shapely

from kitegully.io.raster import GridSpec, Raster
from kitegully.polygons.evaluation import (EvaluationParams, clip_truth, evaluate_against_truth, observable_region, polygon_scores,
                                           regenerate_table1, table1)
from kitegully.polygons.manual import OperatorParams, operator_outlines

from .polygon_synthetic import CRS

GRID = GridSpec(0.0, 100.0, 0.5, 200, 200, CRS)


def _set(x0, x1):
    return gpd.GeoDataFrame(geometry=[shapely.box(x0, 40, x1, 60)], crs=CRS)


def test_table1_statistics_of_nested_sets():
    auto = {0.5: _set(10, 50), 1.0: _set(12, 48), 1.5: _set(14, 46)}  # 800, 720, 640 m2
    manual = gpd.GeoDataFrame(geometry=[shapely.box(10, 40, 60, 60), shapely.box(20, 40, 40, 60)], crs=CRS)  # 1000, 400
    stats, comp = table1(auto, manual, GRID)
    s = stats.set_index("statistic")
    assert s.loc["mean_area_m2", "auto"] == pytest.approx(720.0)
    assert s.loc["sd_area_m2", "auto"] == pytest.approx(80.0)
    assert s.loc["intersection_m2", "auto"] == pytest.approx(640.0)
    assert s.loc["union_m2", "manual"] == pytest.approx(1000.0)
    assert s.loc["min_over_max_pct", "manual"] == pytest.approx(40.0)
    c = comp.set_index("statistic")["value"]
    assert c.iloc[0] == pytest.approx(100.0)  # A inside U
    assert c.iloc[1] == pytest.approx(100.0)  # I inside A
    assert c.iloc[2] == pytest.approx(80.0)  # A covers 800 of U's 1000
    assert c.iloc[3] == pytest.approx(2.0)  # |A| / |I|


def test_operators_are_seeded_and_differ():
    truth = gpd.GeoDataFrame({"gully_id": [0, 1]}, geometry=[shapely.box(10, 40, 60, 50), shapely.box(10, 70, 12, 90)], crs=CRS)
    depth = {0: 1.0, 1: 0.1}
    a = operator_outlines(truth, depth, OperatorParams(), 5)
    b = operator_outlines(truth, depth, OperatorParams(), 5)
    assert np.allclose(a["area_m2"], b["area_m2"])
    assert a["area_m2"].std() > 0
    # the 0.1 m deep gully is below every operator's visibility
    assert all(g.intersection(shapely.box(10, 70, 12, 90)).area < 1.0 for g in a.geometry)


def test_scores_per_gully():
    truth = gpd.GeoDataFrame({"gully_id": [0]}, geometry=[shapely.box(10, 40, 50, 60)], crs=CRS)
    info = pd.DataFrame({"gully_id": [0], "kind": ["gully"], "mean_width_m": [20.0]})
    auto = gpd.GeoDataFrame(geometry=[shapely.box(30, 40, 70, 60)], crs=CRS)
    sc = polygon_scores(auto, truth, info, GRID, EvaluationParams(zone_m=10.0))
    row = sc.iloc[0]
    assert row["recall"] == pytest.approx(0.5)
    assert row["precision"] == pytest.approx(400 / 600)  # mapped cells beyond the 10 m zone do not count for the gully
    assert sc.set_index("kind").loc["all", "precision"] == pytest.approx(0.5)


def test_truth_under_open_water_is_left_out_and_reported():
    # one 4 m wide gully, 80 m long; its lower 30 m lie under a reservoir (class 8) that no survey sees through
    grid = GridSpec(0.0, 100.0, 0.5, 200, 200, CRS)
    truth = gpd.GeoDataFrame({"gully_id": [0], "kind": ["gully"], "area_m2": [320.0]}, geometry=[shapely.box(10, 48, 90, 52)], crs=CRS)
    lines = gpd.GeoDataFrame({"gully_id": [0, 0], "kind": ["gully", "gully"], "shape": ["V", "V"], "width_m": [4.0, 4.0],
                              "depth_m": [1.0, 1.0], "depth_max_m": [1.0, 1.0], "length_m": [40.0, 40.0]},
                             geometry=[shapely.LineString([(10, 50), (50, 50)]), shapely.LineString([(50, 50), (90, 50)])], crs=CRS)
    lc = np.full((grid.height, grid.width), 3, np.uint8)
    lc[:, 120:] = 8  # x >= 60 m: water
    classes = pd.DataFrame({"code": [3, 8], "name": ["grass", "water"]})
    region = observable_region(grid, Raster(lc, grid), classes)
    assert region.area == pytest.approx(60 * 100)
    polys, cl = clip_truth(truth, lines, region)
    assert polys["area_m2"].iloc[0] == pytest.approx(200.0) and cl["length_m"].sum() == pytest.approx(50.0)
    # a map of exactly the visible reach, one section per 10 m of it (true V area 2 m2)
    auto = gpd.GeoDataFrame(geometry=[shapely.box(10, 48, 60, 52)], crs=CRS)
    sections = gpd.GeoDataFrame({"polygon_id": 1, "station_m": np.arange(5) * 10.0, "width_m": 4.0, "depth_m": 1.0, "area_m2": 2.0, "slab_m": 10.0},
                                geometry=[shapely.LineString([(x, 46), (x, 54)]) for x in (15, 25, 35, 45, 55)], crs=CRS)
    cfg = {"zone_m": 10.0, "wide_gully_m": 2.0, "match_distance_m": 2.0}
    ev = evaluate_against_truth(auto, sections, truth, lines, grid, cfg, 2.0, region=region)
    sc = ev["scores"].set_index("kind")
    assert sc.loc["all", "iou"] == pytest.approx(1.0)
    e = ev["errors"].set_index("quantity")
    assert e.loc["volume, all sections vs all true gullies (m3)", "error_pct"] == pytest.approx(0.0)
    assert e.loc["true volume not observable (under open water, beyond the DEM) (m3)", "true"] == pytest.approx(60.0)
    assert e.loc["volume, all sections vs all true gullies incl. not observable (m3)", "error_pct"] == pytest.approx(-37.5)
    assert ev["volumes"]["volume_not_observable_m3"].iloc[0] == pytest.approx(60.0)
    # without the region the reach under water counts as missed
    whole = evaluate_against_truth(auto, sections, truth, lines, grid, cfg, 2.0)
    assert whole["scores"].set_index("kind").loc["all", "recall"] == pytest.approx(50 / 80)


def test_operators_do_not_digitise_under_open_water():
    grid = GridSpec(0.0, 100.0, 0.5, 200, 200, CRS)
    truth = gpd.GeoDataFrame({"gully_id": [0], "kind": ["gully"], "area_m2": [800.0]}, geometry=[shapely.box(10, 40, 90, 50)], crs=CRS)
    lines = gpd.GeoDataFrame({"gully_id": [0], "kind": ["gully"], "shape": ["V"], "width_m": [10.0], "depth_m": [1.0], "depth_max_m": [1.0],
                              "length_m": [80.0]}, geometry=[shapely.LineString([(10, 45), (90, 45)])], crs=CRS)
    region = shapely.box(0, 0, 60, 100)
    auto = {0.5: gpd.GeoDataFrame(geometry=[shapely.box(10, 40, 60, 50)], crs=CRS)}
    habits = {"count": 3, "min_visible_depth_m": [0.2, 0.5], "edge_bias_sd_m": 0.5, "edge_noise_sd_m": [0.2, 0.6],
              "edge_noise_wavelength_m": 10.0, "generalisation_m": [0.25, 1.5]}
    _, _, ops = regenerate_table1(auto, truth, lines, grid, habits, 1, 2.0, region=region)
    assert len(ops) == 3 and all(g.area > 100.0 for g in ops.geometry)
    assert all(g.intersection(shapely.box(62, 0, 100, 100)).area < 1.0 for g in ops.geometry)
