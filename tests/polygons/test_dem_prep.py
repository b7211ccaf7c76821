"""DEM preparation: minimum z per cell, moving planes only in empty cells."""

from __future__ import annotations

import numpy as np
import pytest

from kitegully import InputError
from kitegully.io.raster import GridSpec
from kitegully.polygons.dem_prep import fill_moving_planes, min_z_resample

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
