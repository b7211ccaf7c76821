"""DEM preparation: minimum z per cell, moving planes only in empty cells."""

from __future__ import annotations

import numpy as np
import pytest

from kitegully import InputError
from kitegully.io.raster import GridSpec
from kitegully.polygons.dem_prep import fill_moving_planes, min_z_resample, open_water, prepare_dem

from .polygon_synthetic import CRS


def test_min_z_keeps_the_lowest_source_cell():
    grid = GridSpec(0.0, 10.0, 0.2, 50, 50, CRS)
    z = np.full((50, 50), 5.0, np.float32)
    z[3, 4] = 1.0  # centre (0.9, 9.3) -> target cell (row 1, col 1) at 0.5 m
    out, tg = min_z_resample(z, grid, 0.5)
    assert tg.cell == 0.5 and out.shape == (20, 20)
    assert out[1, 1] == 1.0 and out[0, 0] == 5.0
    with pytest.raises(InputError, match="finer than the input DEM cell"):
        min_z_resample(z, grid, 0.1)


def test_moving_planes_fill_only_empty_cells_exactly_on_a_plane():
    r, c = np.mgrid[0:40, 0:40]
    z = (3.0 + 0.1 * c - 0.05 * r).astype(np.float32)
    holes = np.zeros_like(z, bool)
    holes[10:14, 20:25] = True
    zin = z.copy()
    zin[holes] = np.nan
    out, n = fill_moving_planes(zin, 0.5, 10, 10.0)
    assert n == holes.sum()
    assert np.allclose(out[holes], z[holes], atol=1e-4)
    assert np.array_equal(out[~holes], zin[~holes])


def _reservoir_dsm(seed: int = 0):
    """A 0.2 m DSM on a plane with a 60 x 60 m reservoir matched at 30 % of its cells (at the
    water surface), a 4 x 4 m matching gap on land and a 100 x 2 m strip of land half matched."""
    grid = GridSpec(0.0, 200.0, 0.2, 1000, 1000, CRS)
    r, c = np.mgrid[0:1000, 0:1000]
    z = (100.0 + 0.02 * c * 0.2).astype(np.float32)
    rng = np.random.default_rng(seed)
    lake = (r >= 100) & (r < 400) & (c >= 100) & (c < 400)
    z[lake] = np.where(rng.random(int(lake.sum())) < 0.3, 102.0, np.nan)
    z[600:620, 600:620] = np.nan  # a matching gap: filled by the moving planes
    strip = (r >= 800) & (r < 810) & (c >= 100) & (c < 600)
    z[strip & (rng.random(z.shape) < 0.5)] = np.nan
    return z, grid, lake


def test_open_water_is_a_large_region_that_found_few_matches():
    z, grid, lake = _reservoir_dsm()
    water = open_water(np.isfinite(z), grid.cell, 4.5, 2500.0)
    inner = np.zeros_like(lake)
    inner[115:385, 115:385] = True  # half a window inside the shore
    assert water[inner].all()
    # a band of up to half a window along the shore sees land in half its window: (60 - 2 x 2.25)^2 / 60^2 = 0.86
    assert water[lake].mean() > 0.86
    assert not water[~lake].any()  # neither the 16 m2 gap nor the half-matched strip
    # smaller than the minimum area: no water
    assert not open_water(np.isfinite(z), grid.cell, 4.5, 4000.0).any()


def test_prepare_dem_leaves_open_water_empty_and_fills_gaps():
    z, grid, lake = _reservoir_dsm()
    out, tg, info = prepare_dem(z, grid, 0.5, 10, 10.0, water_min_area_m2=2500.0, water_window_m=4.5)
    assert info["water_cells"] > 0.86 * 120 * 120
    assert np.isnan(out[45:155, 45:155]).all()  # the reservoir (rows/cols 40-160 at 0.5 m) stays empty
    assert np.isfinite(out[240:248, 240:248]).all()  # the land gap is filled
    assert np.isfinite(out[320:324, 40:240]).all()
    off, _, info_off = prepare_dem(z, grid, 0.5, 10, 10.0)
    assert info_off["water_cells"] == 0 and np.isfinite(off[45:155, 45:155]).all()  # off: the water surface is filled
