"""Automatic gully-head detection on constructed DEMs (gully/heads.py)."""

from __future__ import annotations

import numpy as np
import pytest

from kitegully import InputError
from kitegully.gully.heads import HeadDetectionParams, detect_heads, flow_accumulation
from kitegully.io.raster import GridSpec
from kitegully.terrain.fill import priority_flood_fill
from kitegully.terrain.flats import flow_directions

CELL = 0.2
P = HeadDetectionParams(scale_m=2.0, relief_k=3.0, dsm_sigma_z_m=0.05, slope_window_m=1.0, area_slope_a=0.025,
                        area_slope_b=0.4, min_channel_length_m=10.0)


def _grid(n):
    return GridSpec(x0=0.0, y0=n * CELL, cell=CELL, width=n, height=n, crs="EPSG:32632")


def _valley(n=400, head_y=60.0, depth=0.8, width=2.0, noise=0.01, seed=0):
    """A 10 % slope draining south into a hollow (5 % side slopes, as channel heads sit at the foot of
    convergent hollows) with a V channel along x = 40 m from y = head_y down to the edge."""
    grid = _grid(n)
    xs, ys = grid.cell_centres()
    X, Y = np.meshgrid(xs, ys)
    z = 0.1 * Y + 0.05 * np.abs(X - 40.0)  # the hollow: all the slope above the head drains to x = 40 m
    d = depth * np.clip(1 - np.abs(X - 40.0) / (width / 2), 0, None) * np.clip((head_y - Y) / 0.4, 0, 1)
    z = z - d + np.random.default_rng(seed).normal(0, noise, z.shape)
    return z.astype(np.float32), grid


def _detect(z, grid):
    filled, _ = priority_flood_fill(z, 0.0)
    dirs, _, _ = flow_directions(filled)
    idx, stats = detect_heads(z, filled, dirs, grid, P)
    xs, ys = grid.cell_centres()
    r, c = np.divmod(idx, grid.width)
    return np.column_stack([xs[c], ys[r]]), stats


def test_channel_head_found_at_its_known_start():
    z, grid = _valley()
    heads, _ = _detect(z, grid)
    assert len(heads) >= 1
    d = np.hypot(heads[:, 0] - 40.0, heads[:, 1] - 60.0)
    assert d.min() < 2.0  # the head within 2 m of where the channel starts
    # nothing starts on the open slope far from the channel
    assert np.all(np.abs(heads[:, 0] - 40.0) < 3.0)


def test_no_head_on_a_plane_or_in_a_round_pit():
    grid = _grid(300)
    xs, ys = grid.cell_centres()
    X, Y = np.meshgrid(xs, ys)
    plane = (0.1 * Y + np.random.default_rng(1).normal(0, 0.01, X.shape)).astype(np.float32)
    assert len(_detect(plane, grid)[0]) == 0
    pit = plane - 0.8 * np.clip(1 - np.hypot(X - 30, Y - 30) / 1.5, 0, None)
    assert len(_detect(pit.astype(np.float32), grid)[0]) == 0


def test_shallow_channel_below_the_noise_threshold_is_not_a_head():
    # 4 cm deep: with the hollow's own concavity (~0.08 m at sigma 2 m) still below 3 x 0.05 m
    z, grid = _valley(depth=0.04)
    assert len(_detect(z, grid)[0]) == 0


def test_flow_accumulation_counts_upstream_cells():
    dirs = np.full((1, 5), 4, dtype=np.uint8)  # every cell drains east
    dirs[0, 4] = 255
    area, recv = flow_accumulation(dirs, 2.0)
    assert area.ravel().tolist() == [4.0, 8.0, 12.0, 16.0, 20.0]
    assert recv.tolist() == [1, 2, 3, 4, -1]
    assert recv.dtype == np.int32  # 4 bytes a cell below 2**31 cells (80 M-cell grids: 0.3 GB, not 0.6)


def test_from_config_names_the_missing_key():
    with pytest.raises(InputError, match="gully.automatic_heads: missing key"):
        HeadDetectionParams.from_config({"scale_m": 2.0})
    with pytest.raises(InputError, match="must be > 0"):
        HeadDetectionParams.from_config(dict(P.__dict__, relief_k=0))


def test_dsm_noise_from_checkpoints_feeds_a_null_sigma():
    import pandas as pd

    from kitegully.gully.heads import dsm_noise_at_checkpoints

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


def test_no_head_at_the_foot_of_a_hedgerow_on_a_dsm():
    # a hedgerow (3 m wide, 2 m high) across the 10 % slope, ending 10 m from the DEM edges: a
    # Gaussian of sigma 2 m spreads it, so the ground at its foot looks incised; the ground surface does not
    grid = _grid(300)
    X, Y = np.meshgrid(*grid.cell_centres())
    z = 0.1 * Y + np.random.default_rng(4).normal(0, 0.01, X.shape)
    hedge = 2.0 * np.clip(1 - np.abs(Y - 30.0) / 1.5, 0, None) ** 0.3 * ((X > 10) & (X < 50))
    assert len(_detect((z + hedge).astype(np.float32), grid)[0]) == 0
    # the channel of the valley test is still found with a hedge along the slope 20 m from it
    zv, gv = _valley()
    Xv, _ = np.meshgrid(*gv.cell_centres())
    heads, _ = _detect((zv + 2.0 * np.clip(1 - np.abs(Xv - 20.0) / 1.5, 0, None) ** 0.3).astype(np.float32), gv)
    assert len(heads) >= 1 and np.hypot(heads[:, 0] - 40.0, heads[:, 1] - 60.0).min() < 2.0
    assert np.all(np.abs(heads[:, 0] - 40.0) < 3.0)


def test_ground_surface_removes_a_shrub_and_keeps_a_sloping_plane_and_a_valley():
    from kitegully.gully.heads import ground_surface

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
    from kitegully.gully.heads import surface_roughness

    rng = np.random.default_rng(5)
    relief = rng.normal(0, 0.07, 100_000)
    relief[:3000] = 1.0  # 3 % of the cells in gullies do not move it
    assert surface_roughness(relief) == pytest.approx(0.07, rel=0.05)
    assert surface_roughness(np.array([np.nan])) == 0.0


def test_rough_surface_raises_the_incision_threshold():
    # furrow-like micro-relief of 0.1 m SD at 1 m: with DSM noise 0.01 m alone the threshold would be 0.03 m
    z, grid = _valley(noise=0.0)
    rng = np.random.default_rng(6)
    import scipy.ndimage as ndi

    rough = ndi.gaussian_filter(rng.standard_normal(z.shape), 1.0 / CELL)
    z = (z + 0.1 * rough / rough.std()).astype(np.float32)
    filled, _ = priority_flood_fill(z, 0.0)
    dirs, _, _ = flow_directions(filled)
    _, stats = detect_heads(z, filled, dirs, grid, HeadDetectionParams(**dict(P.__dict__, dsm_sigma_z_m=0.01)))
    assert stats["relief_threshold_m"] == pytest.approx(3 * stats["surface_roughness_m"])
    assert stats["surface_roughness_m"] > 0.03


def _flat_floored_channel(n=400, head_y=60.0, depth=0.8, floor_m=2.0, bank_m=1.0, x0=40.0):
    """The valley's hollow with a trapezoidal channel: a flat floor ``floor_m`` wide between 1:1.25 banks."""
    grid = _grid(n)
    X, Y = np.meshgrid(*grid.cell_centres())
    z = 0.1 * Y + 0.05 * np.abs(X - x0)
    prof = np.clip((floor_m / 2 + bank_m - np.abs(X - x0)) / bank_m, 0, 1)
    return (z - depth * prof * np.clip((head_y - Y) / 0.4, 0, 1)).astype(np.float32), grid


def test_a_flat_floored_head_is_one_head_not_one_per_floor_corner():
    # without noise the D8 paths down the flat floor run side by side and never join: each corner
    # of the floor (3 m apart) started its own head before; both lie within one head-scale FWHM
    z, grid = _flat_floored_channel()
    heads, stats = _detect(z, grid)
    assert len(heads) == 1 and stats["heads_within_scale"] == 1
    assert np.hypot(heads[0, 0] - 40.0, heads[0, 1] - 60.0) < 2.5


def test_one_head_per_incision_keeps_the_first_of_each_cluster_in_order():
    from kitegully.gully.heads import FWHM_PER_SIGMA, one_head_per_incision

    assert FWHM_PER_SIGMA == pytest.approx(2.3548, abs=1e-4)
    grid = _grid(100)
    # cells (row, col): a cluster of three 0.2-0.6 m apart, one 5 m away, one 4 m from the cluster's second
    rc = np.array([[50, 50], [50, 51], [50, 53], [50, 75], [70, 51]])
    idx = rc[:, 0] * grid.width + rc[:, 1]
    kept = one_head_per_incision(idx, grid, 4.71)
    assert kept.tolist() == [idx[0], idx[3]]  # [4] is 4.0 m from [0]: one incision; [3] is 5 m off
    # the order decides which of a cluster stays: reversed, [4] is kept and drops all three (4.0-4.02 m from it)
    assert one_head_per_incision(idx[::-1], grid, 4.71).tolist() == [idx[4], idx[3]]
    assert one_head_per_incision(idx[:1], grid, 4.71).tolist() == [idx[0]]
    assert one_head_per_incision(idx, grid, 0.1).tolist() == idx.tolist()



def test_what_the_dsm_did_not_observe_does_not_change_the_incision_map():
    # a 3 m gap (a crown the matcher lost) 6 m beside the channel head, interpolated low, flat or high:
    # the incised cells, the roughness and the heads are those of the observed cells alone
    z, grid = _valley()
    X, Y = np.meshgrid(*grid.cell_centres())
    gap = np.hypot(X - 46.0, Y - 55.0) < 1.5
    filled, _ = priority_flood_fill(z, 0.0)
    dirs, _, _ = flow_directions(filled)
    runs = [detect_heads(np.where(gap, z + dz, z).astype(np.float32), filled, dirs, grid, P, observed=~gap)
            for dz in (-0.8, 0.0, 0.8)]
    (h0, s0), *rest = runs
    assert np.hypot(*(np.array(grid.flat_xy(h0)).reshape(-1, 2)[0] - [40.0, 60.0])) < 2.0
    for h, st in rest:
        assert h.tolist() == h0.tolist() and st["incised_cells"] == s0["incised_cells"]
        assert st["surface_roughness_m"] == s0["surface_roughness_m"]
    # taken as observed, the interpolated values do move the map
    seen = detect_heads(np.where(gap, z - 0.8, z).astype(np.float32), filled, dirs, grid, P)[1]
    assert seen["incised_cells"] != s0["incised_cells"]


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
    from kitegully.gully.heads import head_scale_relief, incision_map

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
    from kitegully.gully.heads import head_scale_relief

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


def test_the_detector_finds_the_channel_and_no_head_at_a_building_upslope_of_it():
    # the valley test's channel with a 14 x 9 m, 5 m high building 15 m beside it on the slope
    z, grid = _valley()
    X, Y = np.meshgrid(*grid.cell_centres())
    house = (np.abs(X - 60.0) < 7.0) & (np.abs(Y - 40.0) < 4.5)
    dsm = np.where(house, 0.1 * 44.5 + 0.05 * 20.0 + 5.0, z).astype(np.float32)
    heads, _ = _detect(dsm, grid)
    assert len(heads) >= 1 and np.hypot(heads[:, 0] - 40.0, heads[:, 1] - 60.0).min() < 2.0
    assert np.all(np.abs(heads[:, 0] - 40.0) < 3.0)  # none at the building


def test_a_shared_ground_surface_gives_the_same_reliefs_and_heads_bit_for_bit():
    # the gully map makes the ground surface once for the snapping's plain relief and hands it to the detector
    from kitegully.gully.heads import head_scale_ground, head_scale_relief

    z, grid = _valley()
    X, Y = np.meshgrid(*grid.cell_centres())
    house = (np.abs(X - 60.0) < 7.0) & (np.abs(Y - 40.0) < 4.5)
    gap = np.hypot(X - 46.0, Y - 55.0) < 1.5  # a void the matcher left
    dsm = np.where(house, 0.1 * 44.5 + 0.05 * 20.0 + 5.0, z).astype(np.float32)
    dem = np.where(gap, np.nan, dsm).astype(np.float32)
    ref = head_scale_ground(dem, CELL, P)
    plain, rough = head_scale_relief(dem, CELL, P, reference=ref)
    expected = head_scale_relief(dem, CELL, P)
    np.testing.assert_array_equal(plain, expected[0])
    assert rough == expected[1] and ref.ground is not None  # the plain relief leaves it for the next use
    filled, _ = priority_flood_fill(np.where(gap, dsm, dem), 0.0)
    dirs, _, _ = flow_directions(filled)
    alone = detect_heads(np.where(gap, dsm, dem), filled, dirs, grid, P, observed=~gap)
    shared = detect_heads(np.where(gap, dsm, dem), filled, dirs, grid, P, observed=~gap, reference=ref)
    assert shared[0].tolist() == alone[0].tolist() and shared[1] == alone[1] and len(alone[0]) >= 1
    assert ref.ground is None  # the tall-object relief took it: freed before its second ground surface
    with pytest.raises(ValueError, match="already taken"):
        head_scale_relief(dem, CELL, P, tall_objects_out=True, reference=ref)
