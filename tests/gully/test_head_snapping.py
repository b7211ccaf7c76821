"""Head snapping and tracing-DEM smoothing of the gully network (issue 7 follow-up)."""

import numpy as np
import pytest

from kitegully.gully.network import snap_heads
from kitegully.gully.params import GullyParams
from kitegully.gully.pipeline import map_gullies
from kitegully.io.raster import GridSpec

CELL = 0.2
HEAD_SD = 2.0  # digitising SD of the heads (m), as the twin survey
HALF_FLOOR = 1.0  # half width of the gully floor (m)


def furrowed_gully(nrow: int = 200, ncol: int = 400):
    """Plane falling 2 % east with E-W plough furrows (5 cm, 1 m wavelength), cut by a U gully.

    The gully runs E-W along the middle row: floor 2 m wide, 0.5 m deep, walls 0.5 m wide.
    A head digitised beside it on the field lies in a furrow that runs parallel to the gully
    down to the east edge, so steepest descent from there never enters the gully.
    """
    grid = GridSpec(500000.0, 4000000.0 + nrow * CELL, CELL, ncol, nrow, "EPSG:32632")
    xs = grid.x0 + (np.arange(ncol) + 0.5) * CELL
    ys = grid.y0 - (np.arange(nrow) + 0.5) * CELL
    yc = ys[nrow // 2]
    dy = np.abs(ys - yc)
    notch = 0.5 * np.clip((HALF_FLOOR + 0.5 - dy) / 0.5, 0, 1)
    furrow = 0.05 * np.cos(2 * np.pi * (ys - yc) / 1.0)
    z = 100 - 0.02 * (xs[None, :] - xs[0]) + (furrow - notch)[:, None]
    return grid, z.astype(np.float32), xs, yc


def traced_xy(res):
    return np.concatenate([np.asarray(g.coords) for g in res.lines.geometry])


def test_head_beside_the_gully_is_snapped_into_it_and_follows_the_bed():
    grid, z, xs, yc = furrowed_gully()
    hx, hy = np.array([xs[60]]), np.array([yc + 2.5])  # 1 m outside the gully edge, in a furrow bottom
    # radius 3 sigma of the head position (99 % of 2-D errors): the head lands on the gully floor and its path stays on it
    res = map_gullies(z, grid, hx, hy, GullyParams(head_snap="lowest", head_snap_radius_m=3 * HEAD_SD), workers=1)
    xy = traced_xy(res)
    assert np.hypot(xy[0, 0] - hx[0], xy[0, 1] - hy[0]) <= 3 * HEAD_SD + CELL
    assert np.all(np.abs(xy[:, 1] - yc) <= HALF_FLOOR + CELL)
    assert abs(xy[:, 0].max() - grid.bounds[2]) < CELL  # down to the outlet (east edge)
    assert res.network.n_paths_to_outlet() == 1
    # the old 1 m snapping keeps the head in its furrow: the path runs beside the gully all the way
    old = map_gullies(z, grid, hx, hy, GullyParams(head_snap="lowest", head_snap_radius_m=1.0), workers=1)
    assert np.all(np.abs(traced_xy(old)[:, 1] - yc) > HALF_FLOOR + 0.5)


@pytest.mark.parametrize("method", ["deepest", "patch"])
def test_other_snapping_methods_land_in_the_gully(method):
    grid, z, xs, yc = furrowed_gully()
    hx, hy = np.array([xs[60]]), np.array([yc - 2.5])
    res = map_gullies(z, grid, hx, hy, GullyParams(head_snap=method, head_snap_radius_m=3 * HEAD_SD), workers=1)
    xy = traced_xy(res)
    assert np.all(np.abs(xy[:, 1] - yc) <= HALF_FLOOR + 0.5 + CELL)  # inside the gully (floor or wall)
    assert res.network.n_paths_to_outlet() == 1


def test_snap_fallbacks_and_errors():
    grid = GridSpec(0.0, 10.0, 1.0, 10, 10, "EPSG:32632")
    z = np.arange(100, dtype=np.float64).reshape(10, 10)
    x, y = np.array([5.5]), np.array([4.5])  # cell (5, 5)
    # patch method without a patch in reach: lowest cell within 1 m, i.e. the cell above (4, 5)
    idx, inside = snap_heads(z, grid, x, y, 1.0, "patch", patches=np.zeros((10, 10), np.int32))
    assert inside[0] and idx[0] == 4 * 10 + 5
    patches = np.zeros((10, 10), np.int32)
    patches[5, 6] = 3
    idx, _ = snap_heads(z, grid, x, y, 1.0, "patch", patches=patches)
    assert idx[0] == 5 * 10 + 6
    depth = np.zeros((10, 10))
    depth[6, 5] = 1.0
    idx, _ = snap_heads(z, grid, x, y, 1.0, "deepest", depth=depth)
    assert idx[0] == 6 * 10 + 5
    with pytest.raises(ValueError, match="head snapping"):
        snap_heads(z, grid, x, y, 1.0, "highest")
    with pytest.raises(ValueError, match="depth map"):
        snap_heads(z, grid, x, y, 1.0, "deepest")
    with pytest.raises(ValueError, match="head_snap"):
        GullyParams(head_snap="nearest")


def test_trace_smoothing_leaves_the_depth_map_and_water_alone():
    grid, z, xs, yc = furrowed_gully()
    z[20:80, 250:330] = np.nan  # open water (60 x 80 cells = 192 m2 >= water_min_area_m2 below)
    hx, hy = np.array([xs[60]]), np.array([yc])
    kw = dict(head_snap_radius_m=3 * HEAD_SD, water_min_area_m2=100.0)
    raw = map_gullies(z, grid, hx, hy, GullyParams(**kw), workers=1)
    smooth = map_gullies(z, grid, hx, hy, GullyParams(trace_smoothing_m=0.5, **kw), workers=1)
    np.testing.assert_array_equal(raw.depth, smooth.depth)
    np.testing.assert_array_equal(raw.patch_labels, smooth.patch_labels)
    xy = traced_xy(smooth)
    assert np.all(np.abs(xy[:, 1] - yc) <= HALF_FLOOR + CELL)  # smoothing by σ = 0.5 m keeps a 2 m floor
    assert smooth.network.n_paths_to_outlet() == 1


def test_plane_snapping_is_not_pulled_downslope_off_a_shallow_incision():
    # a shallow channel (0.2 m) running across a 10 % slope; a head digitised 3 m upslope of it:
    # the plain lowest cell within 6 m lies 6 m downslope (0.6 m lower) beyond the channel,
    # the lowest cell below the local slope plane is in the channel
    nrow = ncol = 200
    grid = GridSpec(500000.0, 4000000.0 + nrow * CELL, CELL, ncol, nrow, "EPSG:32632")
    xs, ys = grid.cell_centres()
    X, Y = np.meshgrid(xs - xs[0], ys - ys[-1])
    yc = 20.0
    z = 0.1 * Y - 0.2 * np.clip(1 - np.abs(Y - yc) / 0.6, 0, None) - 0.01 * X
    z = z.astype(np.float32)
    from kitegully.gully.depth import depth_map
    smoothed, depth = depth_map(z, CELL, 6.0)
    hx, hy = np.array([xs[100]]), np.array([ys[-1] + yc + 3.0])
    idx_low, _ = snap_heads(z, grid, hx, hy, 6.0, "lowest")
    idx_plane, _ = snap_heads(z, grid, hx, hy, 6.0, "plane", smoothed=smoothed)
    y_of = lambda i: ys[i // ncol] - ys[-1]  # noqa: E731
    assert abs(y_of(idx_plane[0]) - yc) <= 0.6
    assert y_of(idx_low[0]) < yc - 2.0
    with pytest.raises(ValueError, match="needs the smoothed DEM"):
        snap_heads(z, grid, hx, hy, 6.0, "plane")


def test_both_keeps_only_automatic_heads_beyond_the_snapping_radius():
    from kitegully.gully.pipeline import new_heads

    grid = GridSpec(0.0, 20.0, 1.0, 20, 20, "EPSG:32632")
    auto = np.array([5 * 20 + 5, 5 * 20 + 15, 15 * 20 + 10])  # cell centres (5.5, 14.5), (15.5, 14.5), (10.5, 4.5)
    kept = new_heads(auto, grid, np.array([7.0]), np.array([14.0]), radius_m=6.0)
    assert kept.tolist() == [5 * 20 + 15, 15 * 20 + 10]
    assert new_heads(auto, grid, np.zeros(0), np.zeros(0), 6.0).tolist() == auto.tolist()
