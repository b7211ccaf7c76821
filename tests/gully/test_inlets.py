"""kitegully.gully.inlets: channels entering the DEM across its edge, on constructed DEMs."""

from __future__ import annotations

import numpy as np
import pytest

from kitegully.gully.depth import depth_map
from kitegully.gully.heads import HeadDetectionParams
from kitegully.gully.inlets import edge_inlets, outer_edge_distance, route_courses
from kitegully.gully.patches import depth_patches
from kitegully.gully.params import GullyParams
from kitegully.gully.pipeline import map_gullies
from kitegully.io.raster import GridSpec
from kitegully.terrain.fill import priority_flood_fill

CELL = 0.5
NX, NY = 240, 100  # 120 m along x, 50 m across
YC = 25.0  # channel centreline (m)
SIGMA = 6.0
IP = HeadDetectionParams(scale_m=2.0, relief_k=3.0, dsm_sigma_z_m=0.02, slope_window_m=1.0, area_slope_a=0.025,
                         area_slope_b=0.4, min_channel_length_m=10.0)


def _grid():
    return GridSpec(x0=0.0, y0=NY * CELL, cell=CELL, width=NX, height=NY, crs="EPSG:32632")


def plane_with_channel(slope_x: float, channel_x=(0.0, 120.0), scour_at_edge=False, seed=3, rise_m=0.0):
    """A plane falling by ``slope_x`` per metre of x (negative: rising) with a 1 m deep, 4 m wide V channel
    along y = YC over ``channel_x``, 2 cm noise; ``scour_at_edge`` adds a 3 m long, 0.8 m deep hollow at the
    lower edge y = 0 (x 60-63 m); ``rise_m`` lowers the first 8 m from the edge x = 0 by up to that much
    (linearly to 0 at x = 8 m), so that there the surface and the channel's floor rise inward."""
    grid = _grid()
    xs, ys = grid.cell_centres()
    X, Y = np.meshgrid(xs, ys)
    z = 100.0 - slope_x * X - rise_m * np.clip(1.0 - X / 8.0, 0.0, None)
    d = np.abs(Y - YC)
    on = (X >= channel_x[0]) & (X <= channel_x[1])
    z = z - np.where(on, np.clip(1.0 - d / 2.0, 0.0, None), 0.0)
    if scour_at_edge:
        z = z - np.where((X >= 60.0) & (X <= 63.0) & (Y <= 3.0), 0.8, 0.0)
    z = z + np.random.default_rng(seed).normal(0.0, 0.02, z.shape)
    return grid, z.astype(np.float32), xs, ys


def _inlets(z, grid, reach_m=2 * SIGMA, incised=None):
    _s, depth = depth_map(z, grid.cell, SIGMA)
    labels, _t = depth_patches(depth, grid.cell, 0.25, 1.0)
    filled, _n = priority_flood_fill(z.astype(np.float64), 1e-4)
    return edge_inlets(labels, depth, np.isfinite(filled), filled, None, grid.cell, reach_m, incised=incised)[0]


def slope_foot(seed=5):
    """A 40 % slope along y = 0-15 m above a 2 % plain (the concave foot is deep in the σ-scale depth map), with
    a convergent hollow in it: no channel, the slope falls towards -y, away from the edge at y = 50 m."""
    grid = _grid()
    xs, ys = grid.cell_centres()
    X, Y = np.meshgrid(xs, ys)
    yt = 50.0 - Y  # distance from the top edge (m)
    z = 100.0 - 0.02 * yt + 0.38 * np.clip(15.0 - yt, 0.0, None)
    z = z - 1.5 * np.exp(-((X - 60.0) / 10.0) ** 2) * np.clip(1.0 - yt / 40.0, 0.0, None)
    z = z + np.random.default_rng(seed).normal(0.0, 0.02, z.shape)
    return grid, z.astype(np.float32)


def test_a_channel_entering_across_the_edge_is_found_where_it_enters():
    grid, z, xs, ys = plane_with_channel(0.05)  # falls towards +x: the channel enters at x = 0
    ins = _inlets(z, grid)
    assert ins.size == 1
    r, c = np.divmod(ins, grid.width)
    assert xs[c[0]] < 2.0 and abs(ys[r[0]] - YC) <= 1.0


def test_a_channel_whose_floor_rises_at_the_edge_is_found_and_followed_across_the_band():
    # the floor rises 0.2 m over the first 8 m (the 0.05 m/m fall less a 0.6 m dip at the edge): from there
    # everything drains out, as on ensemble twin ens3's wadi; beyond the 12 m band the channel carries water inward
    grid, z, xs, ys = plane_with_channel(0.05, rise_m=0.6)
    _s, depth = depth_map(z, grid.cell, SIGMA)
    labels, _t = depth_patches(depth, grid.cell, 0.25, 1.0)
    filled, _n = priority_flood_fill(z.astype(np.float64), 1e-4)
    starts, courses = edge_inlets(labels, depth, np.isfinite(filled), filled, None, grid.cell, 2 * SIGMA)
    assert starts.size == 1 and len(courses) == 1
    r, c = np.divmod(courses[0], grid.width)
    assert courses[0][0] == starts[0] and xs[c[0]] < 2.0  # starts where it enters
    assert 11.0 <= xs[c[-1]] <= 13.0  # to the band's end
    assert np.abs(ys[r] - YC).max() <= 2.0 and (labels.ravel()[courses[0]] > 0).all()  # through the channel's patch
    assert (np.abs(np.diff(r)) <= 1).all() and (np.abs(np.diff(c)) <= 1).all()  # cell to cell
    # the same DEM through the pipeline: the network runs from the edge along the channel to the far edge
    base = dict(sigma_m=SIGMA, head_snap="lowest", head_snap_radius_m=0.5, trace_smoothing_m=0.5, water_min_area_m2=None)
    on = map_gullies(z, grid, np.zeros(0), np.zeros(0), GullyParams(**base, edge_inlets=True), incision=IP)
    r, c = np.divmod(on.network.cells, grid.width)
    assert on.inlets.size == 1 and xs[c].min() < 2.0 and xs[c].max() > 119.0
    assert np.abs(ys[r] - YC).max() <= 2.0


def test_route_courses_points_each_course_cell_at_the_next():
    dirs = np.full((5, 6), 255, dtype=np.uint8)
    course = np.array([2 * 6 + 0, 2 * 6 + 1, 1 * 6 + 2, 1 * 6 + 3])  # east, north-east, east
    out = route_courses(dirs, [course])
    assert out[2, 0] == 4 and out[2, 1] == 2 and out[1, 2] == 4  # D8_OFFSETS: 4 = (0, +1), 2 = (-1, +1)
    assert out[1, 3] == 255 and (dirs == 255).all()  # the last cell keeps its code; the input is not changed


def test_a_channel_leaving_across_the_edge_is_no_inlet():
    # rises towards +x: the channel enters at x = 120 m and leaves at x = 0
    grid, z, xs, ys = plane_with_channel(-0.05)
    ins = _inlets(z, grid)
    assert ins.size == 1
    assert xs[np.divmod(ins, grid.width)[1][0]] > 118.0


def test_a_channel_starting_inside_the_dem_and_a_scour_at_the_edge_give_none():
    # the channel starts 30 m inside (its head is on the DEM), a short deep hollow touches the edge
    grid, z, _xs, _ys = plane_with_channel(0.05, channel_x=(30.0, 120.0), scour_at_edge=True)
    _s, depth = depth_map(z, grid.cell, SIGMA)
    labels, _t = depth_patches(depth, grid.cell, 0.25, 1.0)
    assert labels[-6:, 120:127].any(), "the scour is a kept depth patch at the edge"
    # the channel leaves at x = 120 m (downstream): no inlet there either
    assert _inlets(z, grid).size == 0


def test_a_concave_slope_foot_is_no_inlet_once_incision_is_asked_for():
    from kitegully.gully.relief import head_scale_relief

    grid, z = slope_foot()
    relief, rough = head_scale_relief(z, grid.cell, IP)
    incised = relief >= IP.relief_k * max(IP.dsm_sigma_z_m, rough)
    # a 10 m band: the hollow's patch crosses it and the slope foot's carries the path another 10 m inward
    assert _inlets(z, grid, reach_m=10.0).size >= 1, "the slope foot's depth patch qualifies on depth alone"
    assert _inlets(z, grid, reach_m=10.0, incised=incised).size == 0
    # the entering channel is incised all the way and stays an inlet
    grid, z, xs, ys = plane_with_channel(0.05)
    relief, rough = head_scale_relief(z, grid.cell, IP)
    assert _inlets(z, grid, incised=relief >= IP.relief_k * max(IP.dsm_sigma_z_m, rough)).size == 1


def test_interior_nodata_is_not_the_edge_but_outer_nodata_is():
    valid = np.ones((50, 60), dtype=bool)
    valid[20:30, 25:35] = False  # open water inside the survey
    valid[:, :5] = False  # the survey's outline
    dist = outer_edge_distance(valid)
    assert dist[25, 30] > 0 and dist[25, 24] == pytest.approx(20.0)
    assert dist[25, 5] == pytest.approx(1.0) and dist[25, 2] == 0.0
    assert dist[0, 30] == pytest.approx(1.0)  # one cell from the grid's border frame


def test_the_pipeline_traces_from_the_inlet_only_when_asked():
    grid, z, xs, ys = plane_with_channel(0.05)
    base = dict(sigma_m=SIGMA, head_snap="lowest", head_snap_radius_m=0.5, trace_smoothing_m=0.5,
                water_min_area_m2=None)
    none = np.zeros(0)
    off = map_gullies(z, grid, none, none, GullyParams(**base))
    on = map_gullies(z, grid, none, none, GullyParams(**base, edge_inlets=True), incision=IP)
    assert off.network.cells.size == 0 and off.inlets.size == 0
    assert on.inlets.size == 1
    r, c = np.divmod(on.network.cells, grid.width)
    assert np.abs(ys[r] - YC).max() <= 1.0  # the path follows the channel
    assert xs[c].max() > 119.0  # down to the far edge
    assert on.extracted_lines["length_m"].sum() > 100.0


def test_edge_inlets_needs_a_positive_reach_and_the_incision_parameters():
    grid, z, _xs, _ys = plane_with_channel(0.05)
    with pytest.raises(ValueError, match="reach_m"):
        _inlets(z, grid, reach_m=0.0)
    with pytest.raises(ValueError, match="automatic_heads"):
        map_gullies(z, grid, np.zeros(0), np.zeros(0), GullyParams(sigma_m=SIGMA, edge_inlets=True))
