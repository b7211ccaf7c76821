"""Head snapping free of slope and curvature bias (relief, incision) and the automatic heads' gap rule (issue 15)."""

from __future__ import annotations

import numpy as np
import pytest

from kitegully.gully.heads import HeadDetectionParams, automatic_head_params, channel_entries, detect_heads
from kitegully.gully.relief import head_scale_relief, incision_map, matched_cells, visible_incisions
from kitegully.gully.network import snap_heads
from kitegully.io.raster import GridSpec
from kitegully.terrain.fill import priority_flood_fill
from kitegully.terrain.flats import flow_directions

CELL = 0.2
P = HeadDetectionParams(scale_m=2.0, relief_k=3.0, dsm_sigma_z_m=0.05, slope_window_m=1.0, area_slope_a=0.025,
                        area_slope_b=0.4, min_channel_length_m=10.0)


def _grid(n):
    return GridSpec(x0=0.0, y0=n * CELL, cell=CELL, width=n, height=n, crs="EPSG:32632")


def steepening_slope_with_a_shallow_channel(n=200, kappa=0.02, yc=20.0, depth=0.2, half_width=0.6):
    """A slope that steepens downslope (profile curvature ``kappa``, 10 % at ``yc``) and a shallow channel.

    The channel (``depth`` deep, V of half width ``half_width``) runs along y = ``yc``. Every cell
    r metres downslope of a point lies about kappa·r²/2 below the tangent plane there (0.36 m at
    r 6 m and kappa 0.02 m⁻¹), deeper than the channel.
    """
    grid = _grid(n)
    xs, ys = grid.cell_centres()
    X, Y = np.meshgrid(xs - xs[0], ys - ys[-1])
    z = 0.1 * (Y - yc) - 0.5 * kappa * (Y - yc) ** 2 - depth * np.clip(1 - np.abs(Y - yc) / half_width, 0, None)
    z = z - 0.01 * X  # a little cross slope so the channel drains
    return grid, z.astype(np.float32), xs, ys


def _y(idx, ys, grid):
    return ys[idx // grid.width] - ys[-1]


def test_relief_snap_lands_in_the_channel_where_lowest_and_plane_are_pulled_off_it():
    grid, z, xs, ys = steepening_slope_with_a_shallow_channel()
    from kitegully.gully.depth import depth_map

    smoothed, _ = depth_map(z, CELL, 6.0)
    relief, _rough = head_scale_relief(z, CELL, P)
    hx, hy = np.array([xs[100]]), np.array([ys[-1] + 22.0])  # digitised 2 m upslope of the channel
    low, _ = snap_heads(z, grid, hx, hy, 6.0, "lowest")
    plane, _ = snap_heads(z, grid, hx, hy, 6.0, "plane", smoothed=smoothed)
    rel, inside = snap_heads(z, grid, hx, hy, 6.0, "relief", relief=relief)
    assert inside[0]
    assert abs(_y(rel[0], ys, grid) - 20.0) <= 0.6  # in the channel
    # slope bias (lowest: downslope edge of the radius) and curvature bias (plane: to the radius, where the
    # curved surface lies kappa r^2/2 below the tangent plane): both off the channel
    assert _y(low[0], ys, grid) < 17.0
    assert abs(_y(plane[0], ys, grid) - 20.0) > 3.0
    with pytest.raises(ValueError, match="relief map"):
        snap_heads(z, grid, hx, hy, 6.0, "relief")


def test_relief_snap_ignores_a_shrub_beside_the_head():
    # a 1 m high shrub 3 m from the head on a plain slope with the channel 2 m away: the ground surface
    # removes the shrub, so the ground at its foot is not "deep" and the head still lands in the channel
    grid, z, xs, ys = steepening_slope_with_a_shallow_channel(kappa=0.0)
    X, Y = np.meshgrid(xs - xs[0], ys - ys[-1])
    z = z + (np.hypot(X - 20.0, Y - 25.0) < 1.0).astype(np.float32)
    relief, _ = head_scale_relief(z, CELL, P)
    rel, _ = snap_heads(z, grid, np.array([xs[100]]), np.array([ys[-1] + 22.0]), 6.0, "relief", relief=relief)
    assert abs(_y(rel[0], ys, grid) - 20.0) <= 0.6


def test_incision_snap_takes_the_nearest_channel_cell_and_keeps_a_head_without_one():
    # 0.3 m deep: its head-scale relief (~0.24 m) is above 3 sigma_z = 0.15 m, so the operator sees it
    grid, z, xs, ys = steepening_slope_with_a_shallow_channel(depth=0.3)
    filled, _ = priority_flood_fill(z, 0.0)
    dirs, _, _ = flow_directions(filled)
    inc = visible_incisions(incision_map(z, CELL, P, roughness=False)[0], CELL, P.slope_window_m)
    entries = channel_entries(inc, dirs, CELL, P.min_channel_length_m)
    assert entries[np.abs(ys - ys[-1] - 20.0) < 0.3].any()  # the channel leads somewhere
    hx, hy = np.array([xs[100], xs[100]]), np.array([ys[-1] + 22.0, ys[-1] + 35.0])  # 2 m and 15 m from it
    idx, inside = snap_heads(z, grid, hx, hy, 6.0, "incision", incised=entries)
    assert inside.all()
    assert abs(_y(idx[0], ys, grid) - 20.0) <= 1.0
    # no incision within 6 m: the head stays on its own cell
    r, c = grid.rowcol(hx[1:], hy[1:])
    assert idx[1] == int(np.rint(r[0])) * grid.width + int(np.rint(c[0]))
    # an isolated dot of incision (smaller than 3 matching windows) is not a visible incision
    dot = np.zeros_like(inc)
    dot[10:14, 10:14] = True
    assert not visible_incisions(dot, CELL, 1.0).any()


def test_no_automatic_head_within_a_matching_window_of_a_dsm_gap():
    n = 400
    grid = _grid(n)
    xs, ys = grid.cell_centres()
    X, Y = np.meshgrid(xs, ys)
    z = 0.1 * Y + 0.05 * np.abs(X - 40.0)
    d = 0.8 * np.clip(1 - np.abs(X - 40.0) / 1.0, 0, None) * np.clip((60.0 - Y) / 0.4, 0, 1)
    z = (z - d + np.random.default_rng(0).normal(0, 0.01, z.shape)).astype(np.float32)
    filled, _ = priority_flood_fill(z, 0.0)
    dirs, _, _ = flow_directions(filled)
    heads, _ = detect_heads(z, filled, dirs, grid, P)
    hx, hy = xs[heads % n], ys[heads // n]
    assert np.hypot(hx - 40.0, hy - 60.0).min() < 2.0  # found without a gap
    gap = np.hypot(X - 40.0, Y - 58.0) < 3.0  # a matching gap over the channel's upper end
    observed = ~gap
    heads2, _ = detect_heads(z, filled, dirs, grid, P, observed=observed)
    dist_to_gap = np.array([np.hypot(X[gap] - xs[h % n], Y[gap] - ys[h // n]).min() for h in heads2])
    assert np.all(dist_to_gap > P.slope_window_m)
    m = matched_cells(observed, CELL, 1.0)
    assert not m[0].any() and not m[:, -1].any()  # the grid edge counts as unmatched
    assert m[200, 200] and not m[gap].any()


def test_relief_and_incision_snapping_need_the_detector_parameters():
    cfg = {k: getattr(P, k) for k in P.__dataclass_fields__}
    z = np.zeros((5, 5), np.float32)
    grid = _grid(5)
    assert automatic_head_params("digitised", cfg, z, grid, head_snap="plane") is None
    assert automatic_head_params("digitised", cfg, z, grid, head_snap="relief") == P
    assert automatic_head_params("digitised", cfg, z, grid, head_snap="incision") == P
    from kitegully.gully.params import GullyParams
    from kitegully.gully.pipeline import map_gullies

    with pytest.raises(ValueError, match="incision-map parameters"):
        map_gullies(z, grid, np.array([0.5]), np.array([0.5]), GullyParams(head_snap="relief"), workers=1)


def test_posterior_snap_in_the_pipeline_lands_in_the_channel_and_not_in_a_gap():
    """map_gullies with ``head_snap: posterior``: the relief spread is measured on the DSM (ρ) and
    the head digitised 2 m upslope of the shallow channel starts its path in the channel; the snap
    reads observed cells only, as ``relief`` does."""
    from kitegully.gully.params import GullyParams
    from kitegully.gully.pipeline import map_gullies

    grid, z, xs, ys = steepening_slope_with_a_shallow_channel(kappa=0.0)
    X, Y = np.meshgrid(xs - xs[0], ys - ys[-1])
    params = GullyParams(head_snap="posterior", head_snap_radius_m=6.0, sigma_m=2.0, water_min_area_m2=None)
    res = map_gullies(z, grid, np.array([xs[100]]), np.array([ys[-1] + 22.0]), params, workers=1, incision=P)
    assert res.heads_inside[0] and abs(_y(res.network.cells[0], ys, grid) - 20.0) <= 0.6
    gap = np.hypot(X - 20.0, Y - 21.0) < 1.5
    dem = np.where(gap, np.nan, z).astype(np.float32)
    res = map_gullies(dem, grid, np.array([xs[100]]), np.array([ys[-1] + 22.0]), params, workers=1, incision=P)
    assert res.heads_inside[0] and not gap.ravel()[res.network.cells[0]]


def test_relief_snap_never_lands_in_a_gap_of_the_dsm():
    # the DSM lost a 1.5-2 m disc over the channel next to the digitised head: the hole-filled surface
    # there is interpolated, so the snapping reads the relief of the observed cells only
    from kitegully.gully.params import GullyParams
    from kitegully.gully.pipeline import map_gullies

    grid, z, xs, ys = steepening_slope_with_a_shallow_channel(kappa=0.0)
    X, Y = np.meshgrid(xs - xs[0], ys - ys[-1])
    params = GullyParams(head_snap="relief", sigma_m=2.0, water_min_area_m2=None)
    for cx, cy, r in ((20.0, 21.0, 1.5), (21.0, 20.0, 2.0)):
        gap = np.hypot(X - cx, Y - cy) < r
        dem = np.where(gap, np.nan, z).astype(np.float32)
        res = map_gullies(dem, grid, np.array([xs[100]]), np.array([ys[-1] + 22.0]), params, workers=1, incision=P)
        assert res.heads_inside[0] and not gap.ravel()[res.network.cells[0]]


def test_posterior_snap_weighs_the_digitising_error_against_the_relief():
    """A head digitised 1.5 m beside its 0.30 m-deep channel, a 0.35 m hollow 5.5 m away (σ 2 m,
    radius 6 m, relief spread ρ 0.073 m, k 3): ``relief`` takes the deeper hollow wherever it lies;
    ``posterior`` stays on the channel (0.05 m = 0.7 ρ of extra relief is not worth 5.5 m at σ 2 m),
    but follows a hollow deep enough to outweigh the distance (0.8 m)."""
    grid = _grid(100)
    xs, ys = grid.cell_centres()
    z = np.zeros((100, 100), np.float32)
    relief = np.zeros((100, 100), np.float32)
    r0, c0 = 50, 50
    relief[r0, c0 + 7:c0 + 40] = 0.30  # the channel, its first cell 1.4 m east of the digitised head
    relief[r0 + 27, c0] = 0.35  # the hollow, 5.4 m south
    hx, hy = np.array([xs[c0]]), np.array([ys[r0]])
    rel, _ = snap_heads(z, grid, hx, hy, 6.0, "relief", relief=relief)
    post, inside = snap_heads(z, grid, hx, hy, 6.0, "posterior", relief=relief, relief_noise_m=0.073, relief_k=3.0)
    assert inside[0]
    assert rel[0] == (r0 + 27) * 100 + c0
    assert post[0] // 100 == r0 and post[0] % 100 == c0 + 7  # the channel's cell nearest the head
    relief[r0 + 27, c0] = 0.8
    post, _ = snap_heads(z, grid, hx, hy, 6.0, "posterior", relief=relief, relief_noise_m=0.073, relief_k=3.0)
    assert post[0] == (r0 + 27) * 100 + c0
    with pytest.raises(ValueError, match="relief noise"):
        snap_heads(z, grid, hx, hy, 6.0, "posterior", relief=relief)
    from kitegully import InputError
    from kitegully.gully.params import GullyParams

    with pytest.raises(InputError, match="head_snap_radius_m"):
        GullyParams(head_snap="posterior", head_snap_radius_m=0.0)
