"""Conditioning: fill depth of dammed pools, closing across dams but not between gullies."""

from __future__ import annotations

import numpy as np

from kitegully.polygons.conditioning import barrier_mask, fill_depth, gully_mask


def test_closing_bridges_a_barrier_gap_but_not_two_separate_gullies():
    cell = 0.5
    fd = np.zeros((60, 80), np.float32)
    # one gully cut by a 3-cell dam (rows 28-30), and a second gully 6 cells to the side
    fd[10:50, 20:30] = 1.0
    fd[28:31, 20:30] = 0.0
    fd[10:50, 36:46] = 1.0
    lab = gully_mask(fd, 0.5, 5, 10.0, cell)
    assert lab.max() == 2
    assert lab[15, 25] == lab[45, 25]  # the dam is bridged
    assert lab[29, 25] == lab[15, 25]
    assert lab[15, 25] != lab[15, 40]  # the neighbour stays apart
    assert (lab[:, 31:35] == 0).all()


def test_small_polygons_dropped_and_seeds_select():
    fd = np.zeros((40, 40), np.float32)
    fd[5:8, 5:8] = 2.0  # 9 cells = 2.25 m2 < 10 m2
    fd[20:30, 20:30] = 2.0  # 25 m2
    fd[20:30, 2:12] = 2.0  # 25 m2, not on the thalweg
    seeds = np.zeros_like(fd, bool)
    seeds[25, 25] = True
    lab = gully_mask(fd, 0.5, 1, 10.0, 0.5, seeds=seeds)
    assert lab.max() == 1 and lab[25, 25] == 1 and lab[6, 6] == 0 and lab[25, 5] == 0


def test_dams_make_pools_on_a_sloping_channel():
    # a channel 1 m deep falling 0.2 m per cell: without dams nothing fills
    h, w = 60, 21
    r, c = np.mgrid[0:h, 0:w]
    z = (0.2 * (h - r) + np.where(np.abs(c - 10) < 4, -1.0, 0.0)).astype(np.float64)
    fd0, _ = fill_depth(z, np.zeros_like(z, bool), 10.0)
    assert np.nanmax(fd0) < 1e-9
    tr = np.zeros_like(z, bool)
    tr[[10, 20, 30, 40, 50], 4:17] = True
    fd, cond = fill_depth(z, barrier_mask(np.zeros_like(tr), tr, 1), 10.0)
    # each pool fills to the channel rim at its downstream dam
    assert np.nanmax(fd) >= 0.99
    assert fd[37, 10] > 0.5 and fd[32, 10] < 0.5


def test_pools_below_the_rims_kept_compartments_beyond_them_dropped():
    from kitegully.polygons.breaklines import detect_breaklines, low_sides
    from .polygon_synthetic import notch_dem

    dem, grid, xc = notch_dem("V", width=8.0, depth=2.0, cross_slope=0.05)
    xs, _ = grid.cell_centres()
    rims_cells, _ = detect_breaklines(dem, grid.cell, 9, 0.2, upper_edges_only=True)
    rims = low_sides(dem, grid.cell, 9, rims_cells)
    fd = np.zeros(dem.shape, np.float32)
    inside = np.abs(xs - xc) <= 3.0  # the incision up to the grown breakline band (rims at +-4 m)
    beyond = (xs - xc >= 5.0) & (xs - xc < 15.0)  # terrain beyond the right rim's band
    fd[100:140, inside] = 1.5
    fd[100:140, beyond] = 1.5
    lab = gully_mask(fd, 0.5, 1, 10.0, grid.cell, edge_cells=1, rims=rims)
    assert (lab[100:140][:, inside] > 0).all()
    assert (lab[100:140][:, beyond] == 0).all()
