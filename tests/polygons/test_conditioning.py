"""Conditioning: fill depth of dammed pools, closing across dams but not between gullies."""

from __future__ import annotations

import numpy as np
import pytest

import shapely

from kitegully.io.raster import GridSpec
from kitegully.polygons.conditioning import bank_held_depth, bank_high_dams, barrier_mask, fill_depth, gully_mask


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


def _grid(h: int, w: int, cell: float = 0.5) -> GridSpec:
    return GridSpec(0.0, h * cell, cell, w, h, "")


def _row_dam(grid: GridSpec, row: int, c0: int, c1: int) -> shapely.LineString:
    y = grid.y0 - (row + 0.5) * grid.cell
    return shapely.LineString([(grid.x0 + (c0 + 0.5) * grid.cell, y), (grid.x0 + (c1 + 0.5) * grid.cell, y)])


def _col_dam(grid: GridSpec, col: int, r0: int, r1: int) -> shapely.LineString:
    x = grid.x0 + (col + 0.5) * grid.cell
    return shapely.LineString([(x, grid.y0 - (r0 + 0.5) * grid.cell), (x, grid.y0 - (r1 + 0.5) * grid.cell)])


def test_a_bank_high_dam_holds_water_up_to_its_lower_bank():
    # a channel 1 m deep falling 0.02 m per cell downstream (rows), across a plane rising 0.03 m per
    # cell to the east: the dam at row 30 spans the channel from the west bank (lower) to the east bank
    h, w = 60, 21
    grid = _grid(h, w)
    r, c = np.mgrid[0:h, 0:w]
    z = 0.02 * (h - r) + 0.03 * c + np.where((np.abs(c - 10) < 4) & (r >= 10), -1.0, 0.0)  # head at row 10
    dam = _row_dam(grid, 30, 0, 20)
    dammed = bank_high_dams([dam], z, grid, grow_cells=1)
    crest = z[30, 6]  # the lower (west) bank: its highest ground west of the channel is its rim
    assert np.allclose(dammed[29:32, 7:14], crest)  # the dam across the channel, grown by a cell
    assert np.array_equal(dammed[29:32, 14:], z[29:32, 14:])  # the east bank stands above the crest
    held = bank_held_depth([dam], z, grid, grow_cells=1)
    assert held[28, 10] == pytest.approx(crest - z[28, 10])  # 0.84 m behind the dam
    assert 0.8 < held[28, 10] < 0.9
    assert np.all((held + z)[held > 0] <= crest + 1e-6)  # the water never stands above the lower bank
    assert np.nanmax(held[33:]) < 1e-9  # nothing below the dam


def test_bank_high_dams_on_open_ground_hold_nothing_where_raised_dams_make_a_deep_pool():
    # four dams crossing on a plane that falls south and rises east: a closed compartment
    h, w = 60, 40
    grid = _grid(h, w)
    r, c = np.mgrid[0:h, 0:w]
    z = 0.02 * (h - r) + 0.03 * c
    dams = [_row_dam(grid, 20, 5, 35), _row_dam(grid, 40, 5, 35), _col_dam(grid, 8, 15, 45), _col_dam(grid, 32, 15, 45)]
    cells = np.zeros(z.shape, bool)
    cells[20, 5:36] = cells[40, 5:36] = cells[15:46, 8] = cells[15:46, 32] = True
    raised, _ = fill_depth(z, barrier_mask(np.zeros_like(cells), cells, 1), 10.0)
    assert raised[30, 20] > 1.0  # the raised dams hold a pool deeper than any gully on this plane
    held = bank_held_depth(dams, z, grid, grow_cells=1)
    assert np.nanmax(held) < 0.05  # each dam's profile has no dip: its crest is its own lowest ground


def test_pools_that_impound_no_channel_are_dropped_and_cells_above_the_banks_too():
    fd = np.zeros((40, 40), np.float32)
    fd[5:15, 5:15] = 2.0  # a gully pool joined to the field beside it (columns 10-14) by raised dams
    fd[25:35, 25:35] = 2.0  # a compartment on a field: raised dams only
    bank_held = np.zeros_like(fd)
    bank_held[5:15, 5:10] = 0.2  # below the banks of the dammed channel
    bank_held[10, 7] = 0.6  # 0.6 m deep at the dam
    lab = gully_mask(fd, 0.5, 1, 10.0, 0.5, bank_held=bank_held)
    assert lab.max() == 1
    assert (lab[5:15, 5:10] == 1).all() and (lab[5:15, 10:15] == 0).all()
    assert (lab[25:35, 25:35] == 0).all()
    assert gully_mask(fd, 1.0, 1, 10.0, 0.5, bank_held=bank_held).max() == 0  # not 1 m deep anywhere
