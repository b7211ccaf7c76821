"""benchmarks/polygons_missed_reaches.py: the cells near the stage's lines."""

from __future__ import annotations

import sys
from pathlib import Path

import geopandas as gpd
import shapely

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "benchmarks"))

import polygons_missed_reaches as pmr  # noqa: E402
from kitegully.io.raster import GridSpec  # noqa: E402


def test_cells_near_a_line_and_none_without_lines():
    grid = GridSpec(0.0, 20.0, 0.5, 40, 40, "EPSG:32632")
    line = gpd.GeoDataFrame(geometry=[shapely.LineString([(0, 10), (20, 10)])], crs=grid.crs)
    near = pmr._near(line, grid, 3.0)
    rows = near.any(axis=1).nonzero()[0]
    # 3 m either side of y = 10 m: rows whose centres lie at 7.25 ... 12.75 m (12 rows of 0.5 m)
    assert near[rows].all() and len(rows) == 12
    assert not pmr._near(line.iloc[:0], grid, 3.0).any()
