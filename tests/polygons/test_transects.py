"""Transects: stations, orthogonality, clipping between the nearest breakline crossings."""

from __future__ import annotations

import numpy as np
import pytest
import shapely

from kitegully.io.raster import GridSpec
from kitegully.polygons.transects import clip_transects, make_transects, outlet_ends, survey_edge_dams, transect_stations


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


def _edge_channel(nx: int = 100, ny: int = 80, cell: float = 0.5):
    """A level plain with a 6 m wide channel running south off the DEM; breakline band on its rims."""
    grid = GridSpec(0.0, ny * cell, cell, nx, ny, "EPSG:32632")
    xs, ys = grid.cell_centres()
    dem = np.tile(100.0 + 0.01 * ys[:, None], (1, nx)).astype(np.float64)
    inside = np.abs(xs - xs[nx // 2]) < 3.0
    dem[:, inside] -= 1.5
    rims = np.zeros((ny, nx), bool)
    rims[:, np.nonzero(inside)[0][[0, -1]] + [-1, 1]] = True  # the first cell outside each wall
    return dem, grid, rims, inside


def test_survey_edge_dam_closes_a_channel_that_leaves_the_dem_between_its_rims():
    dem, grid, rims, inside = _edge_channel()
    xs, ys = grid.cell_centres()
    x_mid = xs[dem.shape[1] // 2]
    exit_end = np.array([[x_mid, ys[-1] + 4.0]])  # thalweg ends 4 m before the south edge
    dam = survey_edge_dams(exit_end, dem, grid, half_length=15.0, reach=15.0, blocked=rims)
    rows, cols = np.nonzero(dam)
    assert set(rows) == {dem.shape[0] - 1}  # on the edge only
    assert np.array_equal(np.sort(cols), np.nonzero(inside)[0])  # the whole channel, stopped by the rims
    far = np.array([[x_mid, ys[-1] + 20.0]])  # 20 m from the edge: beyond the reach
    assert not survey_edge_dams(far, dem, grid, half_length=15.0, reach=15.0, blocked=rims).any()
    open_field = survey_edge_dams(exit_end, dem, grid, half_length=15.0, reach=15.0, blocked=np.zeros_like(rims))
    assert np.nonzero(open_field)[1].size == 2 * int(15.0 / grid.cell) + 1  # no rims: +- the half length


def test_a_survey_edge_dam_also_closes_a_void_left_empty():
    dem, grid, rims, inside = _edge_channel()
    dem[-10:, :] = np.nan  # the channel runs into open water left empty
    xs, ys = grid.cell_centres()
    end = np.array([[xs[dem.shape[1] // 2], ys[-11] + 3.0]])
    rows, cols = np.nonzero(survey_edge_dams(end, dem, grid, 15.0, 15.0, rims))
    assert set(rows) == {dem.shape[0] - 11} and np.array_equal(np.sort(cols), np.nonzero(inside)[0])


def test_outlet_end_is_the_lower_end_of_each_line():
    dem, grid, _, _ = _edge_channel()
    xs, ys = grid.cell_centres()
    x = xs[dem.shape[1] // 2]
    line = shapely.LineString([(x, ys[5]), (x, ys[-5])])  # drawn from the high (north) end
    back = shapely.LineString([(x, ys[-5]), (x, ys[5])])  # drawn from the low end
    for ln in (line, back):
        assert np.allclose(outlet_ends([ln], dem, grid), [[x, ys[-5]]])
    assert outlet_ends([], dem, grid).shape == (0, 2)
