"""NDVI, slope and aspect on planes of known orientation (paper 004 Eqs 1–3)."""

import numpy as np
import pytest

from kitegully import InputError
from kitegully.lowcost.surface import ndvi, slope_aspect


def plane(rows, cols, cell, dzdx, dzdy):
    """z = dzdx·x + dzdy·y on a north-up grid (row 0 is the north edge)."""
    x = (np.arange(cols) + 0.5) * cell
    y = -(np.arange(rows) + 0.5) * cell
    return dzdx * x[None, :] + dzdy * y[:, None]


@pytest.mark.parametrize(
    "dzdx, dzdy, aspect",
    [(-0.1, 0.0, 90.0),   # falls towards the east -> faces east
     (0.1, 0.0, 270.0),   # falls towards the west
     (0.0, -0.1, 0.0),    # falls towards the north
     (0.0, 0.1, 180.0),   # falls towards the south
     (-0.1, -0.1, 45.0)],  # falls towards the north-east
)
def test_aspect_is_the_downslope_azimuth(dzdx, dzdy, aspect):
    slope, asp = slope_aspect(plane(8, 9, 0.5, dzdx, dzdy), 0.5)
    expected_slope = np.degrees(np.arctan(np.hypot(dzdx, dzdy)))
    assert np.allclose(slope, expected_slope, atol=1e-4)
    assert np.allclose((asp - aspect + 180) % 360 - 180, 0.0, atol=1e-4)


def test_slope_of_a_45_degree_plane_and_flat_has_no_aspect():
    slope, asp = slope_aspect(plane(5, 5, 2.0, 1.0, 0.0), 2.0)
    assert np.allclose(slope, 45.0, atol=1e-4)
    flat_slope, flat_aspect = slope_aspect(np.zeros((4, 4)), 1.0)
    assert np.all(flat_slope == 0) and np.all(np.isnan(flat_aspect))


def test_nodata_stays_nodata():
    dem = plane(6, 6, 1.0, 0.2, 0.0)
    dem[2, 2] = np.nan
    slope, asp = slope_aspect(dem, 1.0)
    assert np.isnan(slope[2, 2]) and np.isnan(asp[2, 2])
    assert np.isfinite(slope[5, 5])


def test_ndvi_of_vegetation_soil_and_water():
    nir = np.array([0.50, 0.30, 0.02])
    red = np.array([0.05, 0.28, 0.06])
    v = ndvi(nir, red)
    assert v[0] > 0.8 and abs(v[1]) < 0.05 and v[2] < -0.4


def test_bad_dem_gives_one_sentence():
    with pytest.raises(InputError, match="at least 2 × 2 cells"):
        slope_aspect(np.zeros(5), 1.0)
    with pytest.raises(InputError, match="cell size must be positive"):
        slope_aspect(np.zeros((3, 3)), 0.0)
