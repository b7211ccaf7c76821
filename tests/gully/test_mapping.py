"""Gully library: depth map, patches, network tracing, final map and polygons."""

from __future__ import annotations

import geopandas as gpd
import numpy as np
import pytest
import shapely

from kitegully import InputError
from kitegully.gully.inputs import check_dem, check_heads_on_dem, read_heads
from kitegully.gully.mapping import buffer_mask, final_map
from kitegully.gully.network import network_lines, snap_heads, trace_network
from kitegully.gully.patches import depth_patches
from kitegully.gully.params import GullyParams
from kitegully.gully.pipeline import map_gullies
from kitegully.io.raster import GridSpec
from kitegully.io.vectors import write_vector
from kitegully.terrain.fill import priority_flood_fill

CRS = "EPSG:32632"
CELL = 0.2
SIGMA = 10.0


def valley_grid(h=600, w=900):
    grid = GridSpec(500000.0, 4000000.0, CELL, w, h, CRS)
    xs, ys = grid.cell_centres()
    return grid, xs, ys


def reference_depth_1d(profile: np.ndarray) -> np.ndarray:
    """Depth across an infinitely long straight gully: direct 1-D Gaussian convolution."""
    s = SIGMA / CELL
    r = int(np.ceil(4 * s))
    k = np.exp(-0.5 * (np.arange(-r, r + 1) / s) ** 2)
    k /= k.sum()
    pad = np.pad(profile, r, mode="edge")  # the profile is flat away from the gully
    return np.convolve(pad, k, mode="valid") - profile


def gully_dem(shape: str, width_m: float, depth_m: float, bottom_m: float = 0.0):
    """Plane falling 2 % to the east and 0.5 % to the south, cut by a straight E-W gully."""
    grid, xs, ys = valley_grid()
    yc = ys[grid.height // 2]
    dy = np.abs(ys - yc)
    if shape == "V":
        notch = depth_m * np.clip(1 - dy / (width_m / 2), 0, None)
    else:  # U: flat bottom, linear walls of (width - bottom)/2
        wall = (width_m - bottom_m) / 2
        notch = depth_m * np.clip(((width_m / 2) - dy) / wall, 0, 1)
    plane = 100 - 0.02 * (xs[None, :] - xs[0]) - 0.005 * (ys[:, None] - ys[-1])
    z = (plane - notch[:, None]).astype(np.float32)
    return grid, z, -notch, yc


@pytest.mark.parametrize(
    "shape,width,depth,bottom", [("V", 6.0, 1.5, 0.0), ("V", 12.0, 3.0, 0.0), ("U", 10.0, 2.0, 8.0), ("U", 4.0, 1.0, 3.0)]
)
def test_analytic_gully_found_with_right_width_and_depth(shape, width, depth, bottom):
    grid, z, profile, yc = gully_dem(shape, width, depth, bottom)
    heads_x = np.array([grid.x0 + 5.0])
    res = map_gullies(z, grid, heads_x, np.array([yc + 0.3]), GullyParams(sigma_m=SIGMA), workers=1)
    ref = reference_depth_1d(profile)
    col = grid.width // 2
    # depth profile across the gully equals the direct convolution (float32 at 100 m)
    np.testing.assert_allclose(res.depth[:, col], ref, atol=2e-4)
    # width: cells above the threshold, within one cell of the analytic expectation
    expected_width = np.sum(ref > 0.25) * CELL
    got_width = res.gully[:, col].sum() * CELL
    assert abs(got_width - expected_width) <= CELL + 1e-9
    # physics: the gully floor is lowered by δ = (G*notch)(0) in the smoothed surface,
    # so the detected width is the width at depth 0.25 m + δ below the rim
    delta = depth - ref.max()
    assert 0 < delta < depth * width / (SIGMA * np.sqrt(2 * np.pi))
    if shape == "V":
        assert abs(got_width - width * (1 - (0.25 + delta) / depth)) <= 3 * CELL
    else:
        assert bottom - CELL <= got_width <= width
    assert res.polygons["max_depth_m"].max() == pytest.approx(ref.max(), abs=2e-4)
    # the network runs along the gully floor from the head to the east edge
    assert res.network.n_paths_to_outlet() == 1
    line = res.lines.geometry.iloc[0]
    assert abs(line.coords[-1][0] - grid.bounds[2]) < CELL
    xy = np.asarray(line.coords)
    assert np.all(np.abs(xy[:, 1] - yc) <= bottom / 2 + CELL)  # on the floor
    assert abs(xy[0, 0] - heads_x[0]) <= 1.0 + CELL  # head snapped within 1 m
    # one gully polygon along the whole line, volume ≈ Σ depth · cell²
    assert len(res.polygons) == 1
    sel = res.gully
    assert res.polygons["volume_m3"].iloc[0] == pytest.approx(res.depth[sel].sum() * CELL**2, rel=1e-6)


def test_plane_with_nodata_gives_no_false_gully():
    grid, xs, ys = valley_grid(400, 500)
    z = (100 - 0.08 * (xs[None, :] - xs[0]) + 0.03 * (ys[:, None] - ys[-1])).astype(np.float32)
    z[150:200, 200:260] = np.nan  # interior hole
    z[:, :40] = np.nan  # outside the survey
    z[300:, 400:] = np.nan
    res = map_gullies(z, grid, np.array([xs[100]]), np.array([ys[100]]), GullyParams(), workers=1)
    assert np.nanmax(np.abs(res.depth)) < 1e-3
    assert not res.gully.any()
    assert res.n_hole_cells == 50 * 60
    assert res.network.n_paths_to_outlet() == 1


def test_patch_volume_filter():
    depth = np.zeros((50, 50), dtype=np.float32)
    depth[5:10, 5:10] = 0.5  # 25 cells · 0.04 m² · 0.5 m = 0.5 m³ → dropped
    depth[20:40, 20:30] = 0.6  # 200 · 0.04 · 0.6 = 4.8 m³ → kept
    depth[45, 45] = np.nan
    labels, table = depth_patches(depth, CELL, 0.25, 1.0)
    assert labels.max() == 1 and labels[30, 25] == 1 and labels[7, 7] == 0
    assert sorted(table["volume_m3"].round(6)) == [0.5, 4.8]


def y_network_dem():
    """Two tributary valleys meeting a trunk valley that leaves at the south edge."""
    grid, xs, ys = valley_grid(300, 300)
    x = xs[None, :] - xs[150]
    y = ys[:, None] - ys[-1]  # height above the south edge (m)
    trunk = np.abs(x) * 0.3
    z = 10 + 0.05 * y + trunk
    # two V tributaries joining the trunk at y = 30 m from the NW and NE
    for sgn in (-1, 1):
        d = np.abs((x - sgn * (y - 30)) / np.sqrt(2))
        z = np.where((y > 30) & (np.sign(x) == sgn), np.minimum(z, 10 + 0.05 * y + d * 0.3 + 0.02), z)
    return grid, z.astype(np.float64), xs, ys


def test_network_strahler_order_and_outlet():
    grid, z, xs, ys = y_network_dem()
    filled, _ = priority_flood_fill(z, 1e-4)
    heads_x = np.array([xs[150] - 25.0, xs[150] + 25.0])
    heads_y = np.array([ys[-1] + 55.0, ys[-1] + 55.0])
    idx, inside = snap_heads(z, grid, heads_x, heads_y, 1.0)
    assert inside.all()
    net = trace_network(filled, idx)
    assert net.n_paths_to_outlet() == 1 and net.n_paths_not_at_outlet() == 0
    lines = network_lines(net, grid)
    assert sorted(lines["stream_order"]) == [1, 1, 2]
    trunk = lines[lines["stream_order"] == 2].geometry.iloc[0]
    assert trunk.coords[-1][1] == pytest.approx(ys[-1], abs=1e-9)  # leaves at the south edge
    # the junction lies where the valleys meet (30 m above the south edge) within a cell or two
    assert trunk.coords[0][1] - ys[-1] == pytest.approx(30.0, abs=3 * CELL)
    assert lines["length_m"].sum() == pytest.approx(sum(g.length for g in lines.geometry))
    # clipped to a mask: only runs on the mask survive
    keep = np.zeros((grid.height, grid.width), dtype=bool)
    keep[-50:, :] = True
    clipped = network_lines(net, grid, keep=keep)
    assert clipped["length_m"].sum() == pytest.approx(49 * CELL, abs=1e-6)


def test_snap_heads_outside_and_on_nodata():
    grid, xs, ys = valley_grid(50, 50)
    z = np.ones((50, 50))
    z[10, 10] = 0.5
    z[40:, 40:] = np.nan
    x = np.array([xs[10] + 0.3, xs[45], grid.x0 - 100])
    y = np.array([ys[10], ys[45], ys[5]])
    idx, inside = snap_heads(z, grid, x, y, 1.0)
    assert idx[0] == 10 * 50 + 10  # snapped onto the lowest cell within 1 m
    assert list(inside) == [True, False, False]


def test_buffer_and_whole_patch_variant():
    net = np.zeros((100, 100), dtype=bool)
    net[50, 10:90] = True
    buf = buffer_mask(net, CELL, 2.0)  # 10 cells
    assert buf[40, 50] and not buf[39, 50]
    labels = np.zeros((100, 100), dtype=np.int32)
    labels[30:70, 45:55] = 1
    labels[0:5, 0:5] = 2
    m = final_map(labels, buf)
    assert m.sum() == 21 * 10
    whole = final_map(labels, buf, whole_patches=True)
    assert whole.sum() == 400


def test_input_errors(tmp_path):
    with pytest.raises(InputError, match="dem.tif: the DEM is all nodata"):
        check_dem(np.full((3, 3), np.nan), "dem.tif")
    with pytest.raises(InputError, match="dem.tif: CRS EPSG:4326 does not match"):
        check_dem(np.ones((3, 3)), "dem.tif", "EPSG:4326", CRS)
    with pytest.raises(InputError, match="heads.gpkg: none of the 2"):
        check_heads_on_dem(np.array([False, False]), "heads.gpkg")
    lines = gpd.GeoDataFrame(geometry=[shapely.LineString([(0, 0), (1, 1)])], crs=CRS)
    write_vector(lines, tmp_path / "heads.gpkg")
    with pytest.raises(InputError, match="heads.gpkg: gully heads must be points"):
        read_heads(tmp_path / "heads.gpkg", CRS)
    pts = gpd.GeoDataFrame(geometry=[shapely.Point(1, 2)], crs="EPSG:4326")
    write_vector(pts, tmp_path / "h2.gpkg")
    with pytest.raises(InputError, match="h2.gpkg: CRS"):
        read_heads(tmp_path / "h2.gpkg", CRS)


def test_the_tiled_inputs_keep_one_float64_fill_and_the_tracing_surface_as_its_path(tmp_path):
    from kitegully.gully.inputs import read_tiled_inputs
    from kitegully.io.raster import GridSpec, write_raster

    grid = GridSpec(500000.0, 4001000.0, 0.2, 6, 4, "EPSG:32632")
    z = np.arange(24, dtype=np.float32).reshape(4, 6) + 100.25
    for name in ("filled", "depth", "trace_surface"):
        write_raster(tmp_path / f"{name}.tif", z, grid)
    write_raster(tmp_path / "crowns.tif", (z > 110).astype(np.uint8), grid, nodata=255)
    got = read_tiled_inputs({k: tmp_path / f"{k}.tif" for k in ("filled", "depth", "trace_surface", "crowns")})
    assert sorted(got) == ["crown_mask", "depth", "filled", "trace_surface"]  # no smoothed given: none passed
    assert got["filled"].dtype == np.float64 and np.array_equal(got["filled"], z.astype(np.float64))
    assert got["trace_surface"] == tmp_path / "trace_surface.tif"
    assert got["crown_mask"].dtype == bool and got["crown_mask"].sum() == int((z > 110).sum())
    assert read_tiled_inputs({}) == {}
