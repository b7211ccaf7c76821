"""Least-cost drainage directions (kitegully.terrain.least_cost)."""

import numpy as np
import pytest
from scipy import ndimage

from kitegully.terrain.fill import priority_flood_fill
from kitegully.terrain.flats import flow_directions
from kitegully.terrain.flow import D8_OFFSETS, NO_FLOW, d8_directions, trace_paths
from kitegully.terrain.least_cost import least_cost_directions


def rough_dem(shape=(120, 160), seed=3):
    rng = np.random.default_rng(seed)
    r = np.mgrid[0 : shape[0], 0 : shape[1]][0]
    return ndimage.gaussian_filter(rng.normal(size=shape), 2.0) * 5.0 + 0.02 * r


def follow(dirs, i, limit):
    """Cells visited from flat index ``i`` along ``dirs`` until a cell without direction."""
    h, w = dirs.shape
    seen = [i]
    for _ in range(limit):
        k = dirs.ravel()[i]
        if k == NO_FLOW:
            return seen
        r, c = divmod(i, w)
        i = (r + D8_OFFSETS[k, 0]) * w + c + D8_OFFSETS[k, 1]
        seen.append(i)
    raise AssertionError("no outlet reached: a loop")


def test_on_a_surface_without_depressions_it_is_the_steepest_descent():
    z, _ = priority_flood_fill(rough_dem(), 1e-3)  # every cell has a strictly lower neighbour
    lc, n_uphill = least_cost_directions(z)
    inner = np.zeros(z.shape, bool)
    inner[1:-1, 1:-1] = True
    assert n_uphill == 0
    np.testing.assert_array_equal(lc[inner], d8_directions(z)[inner])


def test_every_cell_of_an_unfilled_dem_with_nodata_reaches_an_outlet_without_loops():
    z = rough_dem()
    z[40:55, 60:90] = np.nan  # an interior hole: its shore is an outlet
    dirs, n_uphill = least_cost_directions(z)
    assert n_uphill > 0  # the rough surface has pits: their routes out drain uphill
    valid = np.isfinite(z)
    assert np.all(dirs[~valid] == NO_FLOW)
    for i in np.flatnonzero(valid.ravel())[::37]:
        path = follow(dirs, int(i), z.size)
        end = path[-1]
        r, c = divmod(end, z.shape[1])
        near_nodata = not np.all(valid[max(r - 1, 0) : r + 2, max(c - 1, 0) : c + 2])
        assert r in (0, z.shape[0] - 1) or c in (0, z.shape[1] - 1) or near_nodata


def basin_with_a_sinuous_channel(n=160):
    """A bowl 3 m deep on a plane falling south, with a meandering channel 0.6 m deep across it.

    The fill floods the bowl's floor to the level where the channel leaves it; the channel
    meanders through that flat.
    """
    r, c = np.mgrid[0:n, 0:n].astype(float)
    z = 10 - 0.05 * r
    d = np.hypot(r - n / 2, c - n / 2)
    z -= np.where(d < 0.35 * n, 3.0 * (1 - (d / (0.35 * n)) ** 2), 0)
    xc = n / 2 + 0.12 * n * np.sin(2 * np.pi * r[:, 0] / (0.4 * n))
    chan = np.abs(c - xc[:, None]) <= 1.0
    z[chan] -= 0.6
    return z, chan


def test_a_path_through_a_filled_basin_follows_the_channel_not_the_flat():
    z, chan = basin_with_a_sinuous_channel()
    head = np.array([2 * z.shape[1] + z.shape[1] // 2])
    lc, _ = least_cost_directions(z)
    fz, n_raised = priority_flood_fill(z, 0.0)
    fd, _, _ = flow_directions(fz)
    assert n_raised > 500  # the bowl's floor was a depression
    on_lc = chan.ravel()[trace_paths(z, head, lc)[0]].mean()
    on_flat = chan.ravel()[trace_paths(fz, head, fd)[0]].mean()
    assert on_lc > 0.98
    assert on_flat < 0.9  # the flat-resolved path cuts across the meanders (84 % when written)


def test_float32_input_gives_the_directions_of_float64():
    z = rough_dem().astype(np.float32)
    a, na = least_cost_directions(z)
    b, nb = least_cost_directions(z.astype(np.float64))
    np.testing.assert_array_equal(a, b)
    assert na == nb


def test_needs_a_2d_array():
    with pytest.raises(ValueError, match="2-D"):
        least_cost_directions(np.zeros(5))
