"""Rules for a DSM with plants: sections on their ground profile, and fill held by the terrain and dams alone."""

from __future__ import annotations

import numpy as np
import pytest
import shapely

from kitegully import InputError
from kitegully.polygons.conditioning import gully_mask, polygons_from_labels
from kitegully.polygons.morphometry import measure_sections
from kitegully.polygons.profiles import axis_gradient, drape, drape_opened_along, ground_profile, section_profile
from kitegully.polygons.stage import PolygonParams

from .polygon_synthetic import notch_dem, true_area


def _shrubs_on_rims(dem, grid, xc, half_width, height=1.0, clump_m=2.0, period_m=4.0):
    """Shrub clumps (``height`` m, ``clump_m`` across, every ``period_m`` along and across) on the 4 m beside each rim."""
    xs, ys = grid.cell_centres()
    x, y = np.meshgrid(xs, ys)
    d = np.abs(x - xc)
    strip = (d > half_width) & (d < half_width + 4.0)
    clump = (np.mod(d - half_width, period_m) < clump_m) & (np.mod(y, period_m) < clump_m)
    return (dem + np.where(strip & clump, height, 0.0)).astype(np.float32)


def _straight_gully(shape, grid, xc, half_width):
    """Labels, polygon and rim band of the notch along y (rows 20-219 of the notch DEM, ``half_width`` each side)."""
    xs, _ = grid.cell_centres()
    lab = np.zeros(shape, np.int32)
    lab[20:220, :] = (np.abs(xs - xc) <= half_width)[None, :]
    rims = np.zeros(shape, bool)
    rims[:, np.abs(np.abs(xs - xc) - (half_width + 0.25)) < 0.3] = True
    return lab, polygons_from_labels(lab, grid, 0.5), rims


def test_ground_profile_removes_a_clump_on_the_rim_and_keeps_the_floor_and_slopes():
    s = np.arange(0.0, 24.0 + 1e-9, 0.25)
    d = np.abs(s - 12.0)
    ground = 100.0 + 0.05 * s - np.where(d < 4.0, 2.0 * (1.0 - d / 4.0), 0.0)  # V 8 m wide, 2 m deep, cross slope 0.05
    z = ground + np.where((d >= 4.0) & (d < 6.0), 1.0, 0.0)  # 2 m clumps, 1 m high, on both rims
    g = ground_profile(z, 0.25, 4.0)
    # the floor is kept exactly; the clumps are gone from both rims. A rim under a clump is read on the first
    # ground beside it: on the right the field rises outwards at 0.05, so the rim reads at most 0.05 x 2 m (the
    # clump) high; on the left it falls outwards, so the rim is read at most 0.05 x 4 m (the segment) low.
    assert np.abs(g - ground)[40:57].max() < 1e-9
    assert (z - g)[64:72].min() > 0.85 and 0.0 < (g - ground)[64] <= 0.05 * 2.0 + 1e-9
    assert 0.05 < (ground - g)[32] <= 0.05 * 4.0 + 1e-9
    dep_dsm, area_dsm = section_profile(s[32:65], z[32:65], "line")  # reference on the clumps
    dep_g, area_g = section_profile(s[32:65], g[32:65], "line")
    assert dep_dsm > 2.4 and dep_g == pytest.approx(2.0, abs=0.15)
    assert area_dsm > 1.4 * true_area("V", 8.0, 2.0)
    assert area_g == pytest.approx(true_area("V", 8.0, 2.0), rel=0.15)  # the wall below the lowered left rim adds a little
    # a clump wider than the segment is not ground-truthed away; segment 0 = the DSM as it is
    wide = ground + np.where((d >= 4.0) & (d < 9.0), 1.0, 0.0)
    assert ground_profile(wide, 0.25, 4.0)[16] == pytest.approx(wide[16])
    assert np.array_equal(ground_profile(z, 0.25, 0.0), z)


@pytest.mark.parametrize("shape", ["V", "U"])
def test_sections_on_the_ground_profile_recover_a_notch_under_rim_shrubs(shape):
    dem0, grid, xc = notch_dem(shape, 8.0, 2.0, cross_slope=0.02)
    dsm = _shrubs_on_rims(dem0, grid, xc, 4.0)
    lab, polys, rims = _straight_gully(dsm.shape, grid, xc, 4.0)
    args = (lab, polys, dsm, dsm, grid, 10.0, "line", 2.0, 1.0, 1.0, "all", rims, 4.5)
    _, s_dsm, _ = measure_sections(*args)
    _, s_g, _ = measure_sections(*args, ground_segment_m=4.0)
    _, s_dtm, _ = measure_sections(lab, polys, dem0, dem0, grid, 10.0, "line", 2.0, 1.0, 1.0, "all", rims, 4.5)
    assert np.median(s_dsm["depth_m"]) > np.median(s_dtm["depth_m"]) + 0.3  # the shrubs lift the reference
    # on the ground profile the DSM gives the DTM's depth (within a cell's rise of the valley's cross slope)
    assert np.abs(s_g["depth_m"].to_numpy() - s_dtm["depth_m"].to_numpy()).max() <= 0.02 * 4.0 + 0.02
    assert np.median(s_g["area_m2"]) == pytest.approx(np.median(s_dtm["area_m2"]), rel=0.05)
    assert np.allclose(s_g["width_m"], s_dtm["width_m"])  # width is the clipped length, untouched
    assert np.allclose(s_g.geometry.length, s_g["width_m"], atol=1e-6)  # the stored line is still the clipped section


def test_held_cells_drop_water_only_the_raised_walls_hold():
    # a gully pool (columns 10-19) held by dams, and beside it a field strip (columns 20-39)
    # flooded only because a raised breakline wall encloses it: fill depth 1 m everywhere
    fd = np.zeros((40, 60), np.float32)
    fd[5:35, 10:40] = 1.0
    held = np.zeros_like(fd)
    held[5:35, 10:20] = 1.0
    seeds = np.zeros(fd.shape, bool)
    seeds[20, 15] = True
    pools = gully_mask(fd, 0.5, 1, 10.0, 0.5, seeds, held=held)
    cells = gully_mask(fd, 0.5, 1, 10.0, 0.5, seeds, held=held, held_cells=True)
    assert (pools > 0).sum() == 30 * 30  # the pool rule keeps the whole connected pool
    assert (cells > 0).sum() == 30 * 10 and (cells[:, 20:] == 0).all()


def test_bad_ground_and_held_settings_are_one_sentence():
    with pytest.raises(InputError, match=r"^polygons.morphometry.ground_segment_m: must be 0 or more, got -4.0$"):
        PolygonParams(ground_segment_m=-4.0)
    with pytest.raises(InputError, match=r"^polygons.conditioning.terrain_held: must be false, true, 'pools' or 'cells', got 'cell'$"):
        PolygonParams(terrain_held="cell")


def _wide_clumps_on_rims(dem, grid, xc, half_width, height=1.0, across_m=6.0, along_m=2.0, period_m=4.0):
    """Clumps ``across_m`` wide across the gully (wider than the 4 m segment: the opening across cannot see past
    them) and ``along_m`` long, every ``period_m`` along it, on the ground beside each rim."""
    xs, ys = grid.cell_centres()
    x, y = np.meshgrid(xs, ys)
    d = np.abs(x - xc)
    clump = (d > half_width) & (d < half_width + across_m) & (np.mod(y, period_m) < along_m)
    return (dem + np.where(clump, height, 0.0)).astype(np.float32)


def test_opening_along_the_axis_sees_past_clumps_the_section_cannot_and_keeps_the_gradient():
    dem0, grid, xc = notch_dem("U", 8.0, 2.0, long_slope=0.15, cross_slope=0.02)  # a steep reach: 0.15 along the gully
    dsm = _wide_clumps_on_rims(dem0, grid, xc, 4.0)
    xs, ys = grid.cell_centres()
    y0 = float(ys[np.flatnonzero(np.mod(ys, 4.0) < 2.0)[60]])  # a station where the clumps stand on both rims
    line = shapely.LineString([(xc - 12.0, y0), (xc + 12.0, y0)])
    axis = shapely.LineString([(xc, ys.max()), (xc, ys.min())])  # downhill, as a medial axis may run
    s0 = ys.max() - y0
    step = 0.25
    g = axis_gradient(axis, s0, np.asarray(dsm, np.float64), grid, step, 4.0)
    assert g == pytest.approx(-0.15, abs=0.01)  # downhill along the axis' direction
    along = np.array([0.0, -1.0])
    _, _, _, z_dsm = drape(line, np.asarray(dsm, np.float64), grid, step)
    s, _, _, z_true = drape(line, np.asarray(dem0, np.float64), grid, step)
    _, _, _, z_al = drape_opened_along(line, np.asarray(dsm, np.float64), grid, step, along, g, 4.0)
    _, _, _, z_flat = drape_opened_along(line, np.asarray(dsm, np.float64), grid, step, along, 0.0, 4.0)
    rim = (np.abs(s - 12.0) > 4.5) & (np.abs(s - 12.0) < 9.5)
    assert (z_dsm - z_true)[rim].min() > 0.9  # the clumps stand on the rims at this station
    assert (ground_profile(z_dsm, step, 4.0) - z_true)[rim].max() > 0.9  # the opening across cannot see past them
    assert np.abs(z_al - z_true)[rim].max() < 0.03  # along the gully it can: the ground between clumps
    assert np.abs(z_al - z_true)[np.abs(s - 12.0) < 3.5].max() < 0.03  # the floor stays where it is
    # without the gradient the opening reads a clumped stretch of a steep reach from the nearest gap's samples
    # standing higher up the fall (a straight slope alone it would keep exactly)
    assert (z_flat - z_true)[rim].max() > 0.05
    assert np.all(z_al <= z_dsm + 1e-9)  # never above the DSM
    _, _, _, z_off = drape_opened_along(line, np.asarray(dsm, np.float64), grid, step, along, g, 0.0)
    assert np.array_equal(z_off, z_dsm)  # no segment: the plain drape


def test_sections_opened_along_the_axis_recover_a_notch_under_wide_rim_clumps():
    dem0, grid, xc = notch_dem("U", 8.0, 2.0, long_slope=0.1, cross_slope=0.02)
    dsm = _wide_clumps_on_rims(dem0, grid, xc, 4.0)
    lab, polys, rims = _straight_gully(dsm.shape, grid, xc, 4.0)
    args = (lab, polys, dsm, dsm, grid, 10.0, "banks", 2.0, 1.0, 1.0, "all", rims, 4.5)
    kw = dict(ground_segment_m=4.0, bank_fit_m=4.5)
    _, s_across, _ = measure_sections(*args, **kw)
    _, s_along, _ = measure_sections(*args, **kw, ground_along_axis=True)
    _, s_dtm, _ = measure_sections(lab, polys, dem0, dem0, grid, 10.0, "banks", 2.0, 1.0, 1.0, "all", rims, 4.5, bank_fit_m=4.5)
    err_across = np.abs(s_across["depth_m"].to_numpy() - s_dtm["depth_m"].to_numpy())
    err_along = np.abs(s_along["depth_m"].to_numpy() - s_dtm["depth_m"].to_numpy())
    assert np.median(err_across) > 0.3  # the clumps lift the banks the reference is fitted to
    assert np.median(err_along) < 0.05 and err_along.max() < 0.15
    assert np.allclose(s_along["width_m"], s_across["width_m"])  # positions and widths untouched
