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
    from kitegully.gully.relief import head_scale_ground, head_scale_relief

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
