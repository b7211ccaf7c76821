"""The head-scale relief (:mod:`kitegully.gully.relief`): ground surface, roughness, noise and tall objects."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from gully.test_heads import CELL, P, _grid
from kitegully import InputError
from kitegully.gully.heads import HeadDetectionParams
from kitegully.gully.relief import (dsm_noise_at_checkpoints, ground_surface, head_scale_relief, incision_map,
                                    surface_roughness)


def test_dsm_noise_from_checkpoints_feeds_a_null_sigma():
    grid = _grid(100)
    rng = np.random.default_rng(3)
    dsm = np.zeros((100, 100), np.float32)
    pts = pd.DataFrame({"id": np.arange(400), "x": rng.uniform(1, 19, 400), "y": rng.uniform(1, 19, 400)})
    pts["z"] = rng.normal(0, 0.2, len(pts))
    sz = dsm_noise_at_checkpoints(dsm, grid, pts)
    assert sz == pytest.approx(0.2, rel=0.15)
    # two checkpoints on gross matching errors (metres) are blunders, not the DSM's noise: left out
    pts.loc[[0, 1], "z"] = [5.3, -2.8]
    assert dsm_noise_at_checkpoints(dsm, grid, pts) == pytest.approx(sz, rel=0.05)
    assert dsm_noise_at_checkpoints(dsm, grid, pts, outlier_nmad=None) > 1.5 * sz  # the plain SD would take them
    p = HeadDetectionParams.from_config(dict(P.__dict__, dsm_sigma_z_m=None), sz)
    assert p.dsm_sigma_z_m == pytest.approx(sz)
    with pytest.raises(InputError, match="dsm_sigma_z_m: null needs checkpoints"):
        HeadDetectionParams.from_config(dict(P.__dict__, dsm_sigma_z_m=None))


def test_ground_surface_removes_a_shrub_and_keeps_a_sloping_plane_and_a_valley():
    grid = _grid(300)
    X, Y = np.meshgrid(*grid.cell_centres())
    ground = 0.1 * Y + 0.02 * X - 0.5 * np.clip(1 - np.abs(X - 40.0) / 1.0, 0, None)
    shrub = 1.5 * (np.hypot(X - 20.0, Y - 30.0) < 1.5)
    z = (ground + shrub).astype(np.float32)
    z[:5, :5] = np.nan
    g = ground_surface(z, CELL, 2.0, 0.0)
    assert np.all(np.isnan(g[:5, :5]))
    inner = (slice(60, 240), slice(60, 240))
    err = np.abs(g - ground)[inner]
    assert np.nanmax(err) < 0.12  # the shrub is gone; the valley and the slope stay (smoothing of Z_L aside)
    assert np.nanmax(g[inner][np.hypot(X - 20.0, Y - 30.0)[inner] < 1.5] - ground[inner][np.hypot(X - 20.0, Y - 30.0)[inner] < 1.5]) < 0.12


def test_surface_roughness_is_the_spread_of_the_ungullied_surface():
    rng = np.random.default_rng(5)
    relief = rng.normal(0, 0.07, 100_000)
    relief[:3000] = 1.0  # 3 % of the cells in gullies do not move it
    assert surface_roughness(relief) == pytest.approx(0.07, rel=0.05)
    assert surface_roughness(np.array([np.nan])) == 0.0


def _crown_row(z, X, Y, radius=3.0, height=6.0, y=30.0):
    """A row of tree crowns (7 m apart) across the slope at ``y``; the DSM and each cell's distance to a crown."""
    crowns = np.zeros(X.shape, bool)
    dist = np.full(X.shape, np.inf)
    for cx in np.arange(10.0, 55.0, 7.0):
        d = np.hypot(X - cx, Y - y)
        crowns |= d < radius
        dist = np.minimum(dist, d - radius)
    cap = height * np.sqrt(np.clip(1 - ((dist + radius) / radius) ** 2, 0, 1))
    return np.where(crowns, z + cap, z).astype(np.float32), dist


@pytest.mark.parametrize("size", [(10.0, 8.0, 4.0), (16.0, 10.0, 4.0)])
def test_no_ring_of_incision_around_a_building_with_tall_objects_left_out(size):
    length, width, height = size
    grid = _grid(300)
    X, Y = np.meshgrid(*grid.cell_centres())
    z = 0.1 * Y + np.random.default_rng(5).normal(0, 0.01, X.shape)
    inside = (np.abs(X - 30) < length / 2) & (np.abs(Y - 30) < width / 2)
    dsm = np.where(inside, 0.1 * (30 + width / 2) + height, z).astype(np.float32)
    beside = np.maximum(np.abs(X - 30) - length / 2, np.abs(Y - 30) - width / 2)
    ring = (beside > 0) & (beside < 4)
    # the noise smoothing's skirt around the walls lifts the reference: incised cells on a ring
    incised, threshold, _ = incision_map(dsm, CELL, P)
    assert incised[ring].sum() > 0
    assert not incision_map(dsm, CELL, P, tall_objects_out=True)[0][ring].any()
    assert np.nanmax(head_scale_relief(dsm, CELL, P, tall_objects_out=True)[0][ring]) < 0.5 * threshold


def test_tall_objects_out_clear_a_crown_row_and_leave_a_channel_beside_a_shrub_alone():
    grid = _grid(300)
    X, Y = np.meshgrid(*grid.cell_centres())
    z = 0.1 * Y + np.random.default_rng(5).normal(0, 0.01, X.shape)
    dsm, dist = _crown_row(z, X, Y)
    ring = (dist > 0) & (dist < 4) & (X > 12) & (X < 50)
    plain = np.nanmax(head_scale_relief(dsm, CELL, P)[0][ring])
    out = np.nanmax(head_scale_relief(dsm, CELL, P, tall_objects_out=True)[0][ring])
    assert plain > 0.1 and out < 0.05
    # a 0.6 m channel with a 1 m shrub on its bank: the shrub is below tall_object_m, nothing changes
    chan = 0.6 * np.clip(1 - np.abs(X - 30.0) / 1.0, 0, None) * (Y < 40)
    shrub = 1.0 * (np.hypot(X - 31.5, Y - 35.0) < 1.2)
    zc = (z - chan + shrub).astype(np.float32)
    a = head_scale_relief(zc, CELL, P)[0]
    b = head_scale_relief(zc, CELL, P, tall_objects_out=True)[0]
    np.testing.assert_array_equal(a, b)
