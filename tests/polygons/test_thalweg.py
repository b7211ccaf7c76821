"""Thalweg: MFD catchment area, TCI, snakes smoothing, thalweg lines on a notch."""

from __future__ import annotations

import numpy as np
import pytest

from kitegully.polygons.thalweg import follow_flow, incised_cells, mfd_catchment_area, snakes_smooth, thalweg_lines, topographic_convergence_index
from .polygon_synthetic import notch_dem


def test_mfd_conserves_area_on_a_plane():
    cell = 0.5
    r, c = np.mgrid[0:50, 0:30]
    z = 100.0 - 0.1 * r * cell + 0.0 * c  # falls to the south; no lateral flow within a row
    acc = mfd_catchment_area(z, cell)
    total = z.size * cell * cell
    assert acc[-1].sum() == pytest.approx(total, rel=1e-9)
    # a cell in the middle collects about its upslope column
    assert acc[25, 15] == pytest.approx(26 * cell * cell, rel=0.05)


def test_tci_highest_in_the_notch_and_thalweg_follows_it():
    dem, grid, xc = notch_dem("V", 8.0, 2.0, cross_slope=0.05)
    tci, sca = topographic_convergence_index(dem, grid.cell, 1.1, 0.001)
    xs, _ = grid.cell_centres()
    axis = int(np.argmin(np.abs(xs - xc)))
    assert tci[200, axis] > np.nanmax(tci[200, : axis - 20]) + 2.0
    lines, cells = thalweg_lines(tci, grid, 9.0, 10.0, 2.0, 1.0, 1.0)
    longest = max(lines, key=lambda l: l.length)
    x = np.asarray(longest.coords)[:, 0]
    assert np.abs(x - xc).max() <= 2 * grid.cell


def test_snakes_keep_ends_and_smooth_noise():
    t = np.linspace(0, 100, 101)
    rng = np.random.default_rng(1)
    xy = np.column_stack([t, 0.3 * rng.standard_normal(t.size)])
    sm = snakes_smooth(xy, 1.0, 1.0)
    assert np.allclose(sm[[0, -1]], xy[[0, -1]])
    assert np.abs(sm[5:-5, 1]).std() < 0.5 * np.abs(xy[5:-5, 1]).std()


def _channel_down_a_slope(h=60, w=21):
    r, c = np.mgrid[0:h, 0:w].astype(float)
    z = 100.0 - 0.1 * r + 0.05 * np.abs(c - 10)  # falls to the south, a V along column 10
    incised = np.abs(c - 10) < 1
    seeds = np.zeros((h, w), bool)
    seeds[0:5, 10] = True
    return z, incised, seeds


def test_follow_flow_bridges_a_short_gap_and_stops_at_a_long_one():
    z, incised, seeds = _channel_down_a_slope()
    incised[30:33] = False  # 3 cells: bridged with gap 4
    incised[45:52] = False  # 7 cells: ends the path
    m = follow_flow(seeds, incised, z, 4)
    rows = np.flatnonzero(m[:, 10])
    assert rows.min() == 0 and rows.max() == 44
    assert m[30:33, 10].all()  # the bridged stretch joins the mask
    assert m.sum() == 45 and not m[:, :10].any() and not m[:, 11:].any()
    # with no bridging the path ends at the first gap
    assert np.flatnonzero(follow_flow(seeds, incised, z, 0)[:, 10]).max() == 29


def test_follow_flow_never_runs_upslope_and_keeps_the_seeds():
    z, incised, _ = _channel_down_a_slope()
    seeds = np.zeros_like(incised)
    seeds[40, 10] = True
    seeds[5, 3] = True  # a seed on non-incised ground stays, and adds nothing: its path leaves at once
    m = follow_flow(seeds, incised, z, 2)
    assert not m[:40, 10].any()  # nothing upslope of the seed
    assert m[40:, 10].all()
    assert m[5, 3] and m[:, 3].sum() == 1 and m[:, :3].sum() == 0


def test_follow_flow_stops_at_nodata():
    z, incised, seeds = _channel_down_a_slope()
    z[20, :] = np.nan  # a void row across the channel
    m = follow_flow(seeds, incised, z, 4)
    assert np.flatnonzero(m[:, 10]).max() == 19


def test_incision_on_the_ground_ignores_a_tree_row_but_keeps_a_channel():
    cell = 0.5
    r, c = np.mgrid[0:120, 0:120].astype(float)
    z = 50.0 - 0.05 * r * cell  # a field sloping south
    trees = (c >= 40) & (c < 48)  # a 4 m wide row of 6 m crowns
    dsm = z + np.where(trees, 6.0, 0.0)
    channel = (c >= 90) & (c < 94)  # a 2 m wide channel, 1 m deep
    dsm = dsm - np.where(channel, 1.0, 0.0)
    beside = (c >= 30) & (c < 40) | (c >= 48) & (c < 58)  # the field within 5 m of the row
    on_dsm = incised_cells(dsm, cell, 0.25, 30.0)
    on_ground = incised_cells(dsm, cell, 0.25, 30.0, ground_window_m=6.5)
    assert on_dsm[beside].mean() > 0.9  # the crowns raise the 30 m mean: open field "incised"
    assert not on_ground[beside].any()
    assert on_ground[channel].all() and on_dsm[channel].all()
    assert not on_ground[trees].any()


def test_incision_nodata_is_never_incised():
    z = np.zeros((40, 40))
    z[10:20, 10:20] = np.nan
    z[25:30, :] = -1.0
    m = incised_cells(z, 0.5, 0.25, 10.0)
    assert not m[10:20, 10:20].any() and m[25:30, 5:35].all()
