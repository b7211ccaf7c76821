"""Depth-map tiles of large sites (issue 21): each tile read with the kernel radius around it."""

from __future__ import annotations

import numpy as np
import pytest

from kitegully.gully.depth import depth_halo_cells, depth_map, depth_map_tile
from kitegully.gully.params import GullyParams
from kitegully.gully.pipeline import map_gullies
from kitegully.io.raster import GridSpec, write_raster
from kitegully.seeds import rng_for
from kitegully.terrain.tiling import split_grid

CELL, SIGMA, TRUNC = 0.5, 3.0, 4.0


def _dem(shape=(97, 131)) -> np.ndarray:
    rng = rng_for(0, "depth_tiles", "dem")
    yy, xx = np.mgrid[0 : shape[0], 0 : shape[1]]
    z = 150.0 - 0.03 * xx + 0.02 * yy + rng.normal(0, 0.2, shape)
    z -= 1.5 * np.exp(-((yy - 40) ** 2) / 8.0)  # a gully along a row
    z[10:14, 20:90] = np.nan  # nodata across tiles
    z[60:97, 0:5] = np.nan  # at the DEM edge
    return z.astype(np.float32)


def test_halo_is_the_kernel_radius_plus_the_gradient_cell():
    assert depth_halo_cells(0.2, 6.0, 4.0) == 121


@pytest.mark.parametrize("counts", [(1, 1), (3, 4)])
def test_depth_tiles_equal_the_whole_depth_map(tmp_path, counts):
    z = _dem()
    grid = GridSpec(500000.0, 4000100.0, CELL, z.shape[1], z.shape[0], "EPSG:32632")
    path = tmp_path / "dem.tif"
    write_raster(path, z, grid)
    ref_s, ref_d = depth_map(z, CELL, SIGMA, TRUNC)
    sm = np.full(z.shape, np.nan, np.float32)
    de = np.full(z.shape, np.nan, np.float32)
    for t in split_grid(z.shape, *counts):
        s, d = depth_map_tile(str(path), t, CELL, SIGMA, TRUNC)
        sm[t.r0 : t.r0 + t.h, t.c0 : t.c0 + t.w] = s
        de[t.r0 : t.r0 + t.h, t.c0 : t.c0 + t.w] = d
    assert np.array_equal(np.isnan(de), np.isnan(ref_d)) and np.array_equal(np.isnan(sm), np.isnan(ref_s))
    # float32 FFT sums relative to each window's mean elevation: equal to ~1e-5 m, not bit for bit
    assert np.nanmax(np.abs(de - ref_d)) < 1e-4
    assert np.nanmax(np.abs(sm - ref_s)) < 1e-4


def test_map_gullies_takes_a_given_depth_map():
    z = _dem()
    grid = GridSpec(500000.0, 4000100.0, CELL, z.shape[1], z.shape[0], "EPSG:32632")
    params = GullyParams(sigma_m=SIGMA, depth_threshold_m=0.3, min_patch_volume_m3=0.1, water_min_area_m2=None)
    hx, hy = np.array([500005.0]), np.array([4000080.0])
    ref = map_gullies(z, grid, hx, hy, params)
    got = map_gullies(z, grid, hx, hy, params, smoothed=ref.smoothed, depth=ref.depth)
    assert np.array_equal(got.gully, ref.gully) and got.gully.any()
    with pytest.raises(ValueError, match="both"):
        map_gullies(z, grid, hx, hy, params, depth=ref.depth)
