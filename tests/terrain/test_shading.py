"""The figures' hillshade (kitegully.terrain.shading.hillshade)."""

from __future__ import annotations

import numpy as np
import pytest

from kitegully.terrain.shading import hillshade


def test_a_plane_is_lit_by_the_sun_s_elevation_and_a_slope_facing_it_brighter():
    flat = np.zeros((20, 30))
    assert np.allclose(hillshade(flat, 0.5, 315.0, 45.0), np.sin(np.radians(45.0)))
    rows, cols = np.mgrid[0:20, 0:30].astype(float)
    west_facing = 0.3 * cols * 0.5  # rises to the east, so it faces west
    assert hillshade(west_facing, 0.5, 270.0, 45.0).mean() > np.sin(np.radians(45.0)) > hillshade(west_facing, 0.5, 90.0, 45.0).mean()
    south_facing = 0.3 * (19 - rows) * 0.5  # row 0 is north: rises to the north, so it faces south
    assert hillshade(south_facing, 0.5, 180.0, 45.0).mean() > np.sin(np.radians(45.0)) > hillshade(south_facing, 0.5, 0.0, 45.0).mean()


@pytest.mark.parametrize("azimuth", [0.0, 135.0, 315.0])
def test_a_tilted_plane_is_lit_by_the_cosine_of_its_normal_and_the_sun(azimuth):
    # z = a·x + b·y with x east, y north; rows run south, so y falls with the row
    a, b, cell, alt = 0.4, -0.25, 0.2, 40.0
    rows, cols = np.mgrid[0:30, 0:40].astype(float)
    z = a * cols * cell - b * rows * cell
    n = np.array([-a, -b, 1.0]) / np.sqrt(1 + a * a + b * b)
    sun = np.array([np.sin(np.radians(azimuth)) * np.cos(np.radians(alt)), np.cos(np.radians(azimuth)) * np.cos(np.radians(alt)),
                    np.sin(np.radians(alt))])
    assert np.allclose(hillshade(z, cell, azimuth, alt), np.clip(n @ sun, 0, 1))


def test_voids_stay_void_and_do_not_spread():
    z = np.random.default_rng(1).normal(0.0, 0.1, (30, 30))
    z[10:14, 10:14] = np.nan
    hs = hillshade(z, 0.5)
    assert np.array_equal(np.isnan(hs), np.isnan(z))
    assert np.all((hs[np.isfinite(hs)] >= 0) & (hs[np.isfinite(hs)] <= 1))
    assert np.isnan(hillshade(np.full((4, 4), np.nan), 0.5)).all()
    assert np.array_equal(z[np.isfinite(z)], z[np.isfinite(z)])  # the input is not filled in place
