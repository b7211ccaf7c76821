"""Gully widening per cross-section: a trapezoid channel widened by a known amount."""

import geopandas as gpd
import numpy as np
import pytest
import shapely
from change.change_synth import CRS, grid, xy

from kitegully.change.widening import edge_width, extend_line, measure_widening, true_widths


def _channel(g, top_width, depth=0.8, slope=0.02):
    """A straight N-S channel of trapezoid section (walls 1:1) in a plane sloping to the east."""
    X, Y = xy(g)
    u = np.abs(X - (g.x0 + 50.0))
    floor = max(top_width - 2 * depth, 0.0) / 2
    d = np.clip(depth - np.clip(u - floor, 0, None), 0, None)
    return (100.0 + slope * (X - g.x0) - d).astype(np.float32)


def test_edge_width_of_a_v_profile():
    s = np.linspace(0.0, 10.0, 201)
    z = np.abs(s - 5.0) - 1.0  # V of depth 1 below the level 0 ends... clipped at 0
    z = np.minimum(z, 0.0)
    w, d = edge_width(s, z, (3.0, 7.0), 0.25, 1.0)
    assert d == pytest.approx(1.0, abs=0.01)
    assert w == pytest.approx(1.5, abs=0.02)  # depth > 0.25 where |s - 5| < 0.75


def test_edge_width_refuses_a_shallow_profile_and_interpolates_short_gaps():
    s = np.linspace(0.0, 10.0, 201)
    z = np.minimum(np.abs(s - 5.0) - 1.0, 0.0)
    w, d = edge_width(s, 0.2 * z, (3.0, 7.0), 0.25, 1.0)  # 0.2 m deep: no channel by the 0.25 m rule
    assert np.isnan(w) and d == pytest.approx(0.2, abs=0.01)
    assert edge_width(s + 0.0, z + 0.3 * s, (3.0, 7.0), 0.25, 1.0)[0] == pytest.approx(1.5, abs=0.02)  # on a slope
    zg = z.copy()
    zg[100:110] = np.nan
    assert edge_width(s, zg, (3.0, 7.0), 0.25, 1.0)[0] == pytest.approx(1.5, abs=0.05)
    zg[20:80] = np.nan
    assert np.isnan(edge_width(s, zg, (3.0, 7.0), 0.25, 1.0)[0])


def test_known_widening_is_measured():
    g = grid(n=200, cell=0.5)
    z1, z2 = _channel(g, 4.0), _channel(g, 5.2)
    secs = gpd.GeoDataFrame({"polygon_id": [1, 1], "station_m": [10.0, 20.0], "width_m": [4.0, 4.0]},
                            geometry=[shapely.LineString([(g.x0 + 48, g.y0 - y), (g.x0 + 52, g.y0 - y)]) for y in (30.0, 60.0)],
                            crs=CRS)
    w = measure_widening(z1, z2, g, secs, 3.0, 0.25, 1.0)
    assert w["widening_m"].notna().all()
    assert w["widening_m"].to_numpy() == pytest.approx(1.2, abs=0.1)
    assert w["width1_m"].to_numpy() == pytest.approx(4.0 - 2 * 0.25, abs=0.1)  # edges at 0.25 m depth on 1:1 walls


def test_true_widths_and_extension():
    line = shapely.LineString([(0, 0), (4, 0)])
    assert extend_line(line, 3.0).length == pytest.approx(10.0)
    polys = gpd.GeoDataFrame(geometry=[shapely.box(-1, -5, 4.5, 5), shapely.box(8, -5, 9, 5)], crs=CRS)
    secs = gpd.GeoDataFrame(geometry=[line], crs=CRS)
    assert true_widths(secs, polys, 3.0)[0] == pytest.approx(5.5)
