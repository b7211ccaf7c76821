"""Evaluation: Table 1 statistics, operators reproducible, scores against truth."""

from __future__ import annotations

import geopandas as gpd
import numpy as np
import pandas as pd
import pytest
import shapely

from kitegully.io.raster import GridSpec
from kitegully.polygons.evaluation import polygon_scores, table1, EvaluationParams
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
