"""Breaklines: Wood's quadratic by convolution kernels, curvature sign, skeleton, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from kitegully import InputError
from kitegully.polygons.breaklines import convexity, detect_breaklines, low_sides, quadratic_coefficients

from .polygon_synthetic import notch_dem


def test_quadratic_coefficients_exact_on_a_quadric():
    cell = 0.5
    r, c = np.mgrid[0:40, 0:50]
    x, y = c * cell, -r * cell
    z = 0.3 * x**2 - 0.2 * y**2 + 0.1 * x * y + 0.5 * x - 0.7 * y
    a, b, cc, d, e = quadratic_coefficients(z, cell, 9)
    i = (20, 25)
    assert a[i] == pytest.approx(0.3, abs=1e-8)
    assert b[i] == pytest.approx(-0.2, abs=1e-8)
    assert cc[i] == pytest.approx(0.1, abs=1e-8)
    # slope terms at the window centre: derivative of the quadric there
    assert d[i] == pytest.approx(2 * 0.3 * x[i] + 0.1 * y[i] + 0.5, abs=1e-6)
    assert e[i] == pytest.approx(-2 * 0.2 * y[i] + 0.1 * x[i] - 0.7, abs=1e-6)


@pytest.mark.parametrize("kind", ["maximum", "plan"])
def test_ridge_is_convex_valley_is_not(kind):
    cell = 0.5
    r, c = np.mgrid[0:41, 0:41]
    x, y = (c - 20) * cell, -(r - 20) * cell
    tilt = 0.1 * y  # a slope along the crest line so plan curvature is defined
    ridge = -0.2 * x**2 + tilt  # a nose: contours bend round it
    valley = 0.2 * x**2 + tilt
    kr = convexity(ridge, cell, 9, kind)[20, 20]
    kv = convexity(valley, cell, 9, kind)[20, 20]
    assert kr > 0.2
    assert kv <= 1e-9


def test_notch_rims_are_breaklines_and_plan_curvature_misses_a_straight_edge():
    dem, grid, xc = notch_dem("V", width=4.0, depth=1.5)
    skel, k = detect_breaklines(dem, grid.cell, 9, 0.2, "maximum")
    xs, _ = grid.cell_centres()
    row = skel[120]
    cols = np.nonzero(row)[0]
    assert len(cols) >= 2
    left, right = xs[cols].min(), xs[cols].max()
    assert left == pytest.approx(xc - 2.0, abs=grid.cell)
    assert right == pytest.approx(xc + 2.0, abs=grid.cell)
    # the bottom of the V (concave) is not a breakline
    assert not skel[120, np.argmin(np.abs(xs - xc))]
    # plan curvature is ~0 on the straight rims, where the maximum curvature is high
    rims = np.abs(np.abs(xs - xc) - 2.0) <= grid.cell
    kp = convexity(dem, grid.cell, 9, "plan")
    assert np.nanmax(np.abs(kp[100:140][:, rims])) < 0.05
    assert np.nanmin(k[100:140][:, np.abs(xs - xc) == 2.0]) > 0.2


def test_window_larger_than_dem_is_one_clear_sentence():
    z = np.zeros((6, 6), np.float32)
    with pytest.raises(InputError, match=r"^polygons.breaklines.window_cells: the DEM \(6 x 6 cells\) is smaller than the 9 x 9 window$"):
        detect_breaklines(z, 0.5, 9, 0.2)


def test_upper_edges_only_drops_a_hedge_but_keeps_gully_rims():
    dem, grid, xc = notch_dem("V", width=8.0, depth=2.0, cross_slope=0.05)
    xs, _ = grid.cell_centres()
    hedge = np.maximum(0.0, 1.0 - np.abs(xs - (xc + 20.0)) / 1.5) * 3.0  # a 3 m high, 3 m wide crown row
    dsm = (dem + hedge[None, :]).astype(np.float32)
    all_, _ = detect_breaklines(dsm, grid.cell, 9, 0.2)
    edges, _ = detect_breaklines(dsm, grid.cell, 9, 0.2, upper_edges_only=True)
    near_hedge = np.abs(xs - (xc + 20.0)) < 3.0
    near_rims = np.abs(np.abs(xs - xc) - 4.0) <= 1.0
    assert all_[:, near_hedge].sum() > 100
    assert edges[:, near_hedge].sum() == 0
    assert edges[:, near_rims].sum() == all_[:, near_rims].sum()


def _notch_with_rim_clumps():
    """V notch 8 m x 2 m; shrub clumps (1 m high, 3 m across, every 4 m) on its east rim; a 3 m hedge in the field.

    The clumps stand on the rim's field edge (centres 0.5 m beyond the rim, so each covers
    the rim), as the twin's shrubs line the gully strips.
    """
    dem, grid, xc = notch_dem("V", width=8.0, depth=2.0, cross_slope=0.05)
    xs, ys = grid.cell_centres()
    x, y = np.meshgrid(xs, ys)
    yc = np.round(y / 4.0) * 4.0  # one clump centre every 4 m along the rim
    clumps = np.maximum(0.0, 1.0 - ((x - (xc + 4.5)) ** 2 + (y - yc) ** 2) / 1.5 ** 2) * 1.0
    hedge = np.maximum(0.0, 1.0 - np.abs(xs - (xc - 20.0)) / 1.5) * 3.0
    return (dem + clumps + hedge[None, :]).astype(np.float32), grid, xc, xs


def test_upper_edge_under_rim_clumps_is_kept_on_the_ground():
    dsm, grid, xc, xs = _notch_with_rim_clumps()
    east = np.abs(xs - (xc + 4.0)) <= 1.0
    west = np.abs(xs - (xc - 4.0)) <= 1.0
    near_hedge = np.abs(xs - (xc - 20.0)) < 3.0
    rows = slice(20, -20)  # away from the DEM's north and south borders
    all_, _ = detect_breaklines(dsm, grid.cell, 9, 0.2)
    on_dsm, _ = detect_breaklines(dsm, grid.cell, 9, 0.2, upper_edges_only=True)
    on_ground, _ = detect_breaklines(dsm, grid.cell, 9, 0.2, upper_edges_only=True, edge_ground_m=4.0)
    n_rows = dsm[rows].shape[0]
    assert all_[rows][:, east].any(axis=1).sum() > 0.9 * n_rows  # the rim is convex on the DSM
    # on the DSM the clumps make the east rim a ridge: most of it is dropped
    assert on_dsm[rows][:, east].any(axis=1).sum() < 0.5 * n_rows
    # on the ground it is an upper edge again, the clean west rim stays, the hedge stays out
    assert on_ground[rows][:, east].any(axis=1).sum() > 0.9 * n_rows
    assert on_ground[rows][:, west].any(axis=1).sum() > 0.9 * n_rows
    assert on_ground[:, near_hedge].sum() == 0
    # the lower side of the kept east rim is the gully (west, towards the axis)
    edges = on_ground.copy()
    edges[:, ~east] = False
    _, cc, _, d_col = low_sides(dsm, grid.cell, 9, edges, ground_m=4.0)
    assert len(cc) > 0 and (d_col < 0).mean() > 0.95


def test_upper_edges_on_the_ground_leave_a_bare_notch_unchanged():
    dem, grid, xc = notch_dem("V", width=8.0, depth=2.0, cross_slope=0.05)
    a, _ = detect_breaklines(dem, grid.cell, 9, 0.2, upper_edges_only=True)
    b, _ = detect_breaklines(dem, grid.cell, 9, 0.2, upper_edges_only=True, edge_ground_m=4.0)
    xs, _ = grid.cell_centres()
    rims = np.abs(np.abs(xs - xc) - 4.0) <= 1.0
    assert a[20:-20][:, rims].sum() > 0
    assert np.array_equal(a[20:-20], b[20:-20])


def test_negative_edge_ground_segment_is_one_clear_sentence():
    from kitegully.polygons import PolygonParams

    with pytest.raises(InputError, match=r"^polygons.breaklines.ground_segment_m: must be 0 or more, got -1.0$"):
        PolygonParams(edge_ground_m=-1.0)
