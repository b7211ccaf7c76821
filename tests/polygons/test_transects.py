"""Transects: stations, orthogonality, clipping between the nearest breakline crossings."""

from __future__ import annotations

import numpy as np
import pytest
import shapely

from kitegully.polygons.transects import clip_transects, make_transects, transect_stations


def test_stations_every_spacing_and_orthogonal():
    line = shapely.LineString([(0, 0), (0, 200)])
    st = transect_stations(line, 50.0)
    assert np.allclose(st, [25, 75, 125, 175])
    tr = make_transects(line, st, 40.0, 5.0)
    (x0, y0), (x1, y1) = tr[0].coords
    assert tr[0].length == pytest.approx(80.0)
    assert y0 == pytest.approx(25.0) and y1 == pytest.approx(25.0)


def test_clipped_between_nearest_crossings_only_when_both_sides_cross():
    line = shapely.LineString([(0, 0), (0, 100)])
    tr = make_transects(line, np.array([20.0, 60.0]), 40.0, 5.0)
    breaklines = [
        shapely.LineString([(-3, -10), (-3, 40)]),   # left rim near station 20 only
        shapely.LineString([(4, -10), (4, 100)]),    # right rim everywhere
        shapely.LineString([(9, -10), (9, 100)]),    # a farther breakline on the right
        shapely.LineString([(-12, -10), (-12, 40)]),  # a farther one on the left
    ]
    out, clipped = clip_transects(tr, breaklines)
    assert clipped.tolist() == [True, False]
    xs = sorted(x for x, _ in out[0].coords)
    assert xs == pytest.approx([-3.0, 4.0])
    assert out[1].length == pytest.approx(80.0)


def test_stations_with_the_floor_computed_once_are_the_same():
    from kitegully.io.raster import GridSpec
    from kitegully.polygons.transects import station_floor

    grid = GridSpec(0.0, 100.0, 0.5, 40, 200, "EPSG:32632")
    r, _ = np.mgrid[0:200, 0:40]
    dem = (10.0 - 0.2 * r + 0.05 * np.sin(r)).astype(np.float32)  # falls 0.1 m per metre southwards
    dem[5, 5] = np.nan
    line = shapely.LineString([(10.0, 99.0), (10.0, 2.0)])
    a = transect_stations(line, 50.0, dem, grid, max_drop=0.5, min_spacing=3.0)
    b = transect_stations(line, 50.0, dem, grid, max_drop=0.5, min_spacing=3.0, floor=station_floor(dem))
    assert len(a) > 4 and np.array_equal(a, b)  # the drop, not the spacing, places them
