"""Fixtures shared by the gully tests."""

from __future__ import annotations

import numpy as np
import pytest

from kitegully.gully.params import GullyParams
from kitegully.gully.pipeline import map_gullies
from kitegully.io.raster import GridSpec

CRS = "EPSG:32632"


@pytest.fixture(scope="module")
def mapped():
    """A plane cut by a straight 1.5 m deep V gully (E-W), head at its upstream end; a nodata corner."""
    grid = GridSpec(500000.0, 4000000.0, 0.5, 300, 200, CRS)
    xs, ys = grid.cell_centres()
    yc = ys[grid.height // 2]
    notch = 1.5 * np.clip(1 - np.abs(ys - yc) / 3.0, 0, None)
    z = (100 - 0.02 * (xs[None, :] - xs[0]) - 0.005 * (ys[:, None] - ys[-1]) - notch[:, None]).astype(np.float32)
    z[:20, :20] = np.nan
    params = GullyParams(sigma_m=5.0, head_snap_radius_m=2.0)
    res = map_gullies(z, grid, np.array([xs[30]]), np.array([yc]), params, workers=1)
    return grid, z, params, res
