"""Sections on every branch of the pruned medial network, and the depth reference at the rims."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.ndimage as ndi
import shapely
from skimage.morphology import thin

from kitegully import InputError
from kitegully.polygons.conditioning import polygons_from_labels
from kitegully.polygons.morphometry import extend_to_rims, measure_sections
from kitegully.polygons.profiles import section_profile
from kitegully.polygons.skeleton import branch_paths
from kitegully.polygons.stage import PolygonParams

from .polygon_synthetic import CRS, notch_dem, true_area
from kitegully.io.raster import GridSpec


def _t_mask(spur: bool = False) -> np.ndarray:
    """A 10-cell-wide channel 200 cells long with a 6-cell-wide tributary 60 cells long (and a bump)."""
    m = np.zeros((120, 240), bool)
    m[20:30, 20:220] = True  # main channel, rows 20-29
    m[30:90, 117:123] = True  # tributary going south from its middle
    if spur:
        m[10:20, 60:64] = True  # a 4 x 10 cell bump: its spur reaches 10 cells beyond a 5-cell half width
    return m


def _branches(mask, min_ext):
    filled = ndi.binary_fill_holes(mask)
    radius = ndi.distance_transform_edt(np.pad(filled, 1))[1:-1, 1:-1]
    return branch_paths(thin(filled), radius, min_ext)


def test_main_stem_then_tributary_with_its_trim():
    br = _branches(_t_mask(), 10.0)
    assert len(br) == 2
    (r0, c0, t0), (r1, c1, t1) = br
    assert t0 == 0.0 and c0.max() - c0.min() > 180  # the main stem runs along the channel
    assert np.ptp(r1) > 50 and np.abs(c1 - 119.5).max() <= 1.5  # the tributary runs south on its axis
    assert 4.0 <= t1 <= 6.0  # it starts inside the main channel (half width 5 cells)


def test_short_spur_is_pruned_and_a_long_branch_kept():
    assert len(_branches(_t_mask(spur=True), 10.0)) == 2  # the bump's spur reaches ~10 - 5 cells beyond the bank: pruned
    assert len(_branches(_t_mask(spur=True), 3.0)) == 3  # kept when the criterion is shorter than its extension


def _tributary_polygon():
    cell = 0.5
    grid = GridSpec(500000.0, 4000000.0, cell, 240, 120, CRS)
    lab = _t_mask().astype(np.int32)
    return lab, polygons_from_labels(lab, grid, 0.5), grid


def test_all_branches_measure_the_tributary_and_longest_does_not():
    lab, polys, grid = _tributary_polygon()
    box = ndi.binary_dilation(lab > 0, iterations=2)  # a 1 m deep box whose walls lie a cell outside the polygon
    dem = np.where(box, 99.0, 100.0).astype(np.float64)
    level = np.full_like(dem, 100.0)  # depth from the pool level ("spill"): 1 m across the polygon
    _, sec_all, m_all = measure_sections(lab, polys, dem, level, grid, 10.0, "spill", 2.0, 1.0, 1.0, branches="all")
    _, sec_one, m_one = measure_sections(lab, polys, dem, level, grid, 10.0, "spill", 2.0, 1.0, 1.0, branches="longest")
    assert set(sec_all["branch"]) == {0, 1} and set(sec_one["branch"]) == {0}
    # the tributary: 3 m wide, 30 m long of which ~2.5 m inside the main channel -> 27.5 m x 3 m2 more volume
    trib = sec_all[sec_all["branch"] == 1]
    assert np.abs(trib["width_m"] - 3.0).max() <= 0.5
    assert m_all["volume_m3"].iloc[0] - m_one["volume_m3"].iloc[0] == pytest.approx(27.5 * 3.0, rel=0.15)
    # total: main 100 m x 5 m2 + tributary; the box has 100 x 5 + 30 x 3 m3
    assert m_all["volume_m3"].iloc[0] == pytest.approx(100 * 5.0 + 27.5 * 3.0, rel=0.1)


def test_section_ends_move_out_to_the_rim_band():
    grid = GridSpec(0.0, 100.0, 0.5, 200, 200, CRS)
    rims = np.zeros((200, 200), bool)
    rims[:, 40] = rims[:, 160] = True  # x = 20.25 m and 80.25 m
    piece = shapely.LineString([(22.0, 50.0), (78.0, 50.0)])
    rims[:, 39] = rims[:, 41] = rims[:, 159] = rims[:, 161] = True  # the breakline dilated to a 3-cell band: its middle is the rim
    line, off = extend_to_rims(piece, rims, grid, 4.5)
    assert off == pytest.approx(1.75, abs=0.26) and line.coords[0][0] == pytest.approx(20.25, abs=0.26)
    assert line.coords[-1][0] == pytest.approx(80.25, abs=0.26)
    same, off0 = extend_to_rims(piece, rims, grid, 0.5)  # rims farther than the search: unchanged
    assert off0 == 0.0 and same.equals(piece)


def test_line_reference_keeps_the_depth_a_cross_slope_takes_from_the_lower_end():
    s = np.linspace(0.0, 8.0, 33)
    d = np.abs(s - 4.0)
    z = 100.0 + 0.1 * s - 2.0 * (1.0 - d / 4.0)  # V 8 m wide, 2 m deep, in a plane rising 0.1 across it
    dep_low, _ = section_profile(s, z, "lower_end")
    dep_line, area_line = section_profile(s, z, "line")
    assert dep_line == pytest.approx(2.0, abs=1e-9) and area_line == pytest.approx(true_area("V", 8.0, 2.0), rel=1e-3)
    assert dep_low == pytest.approx(2.0 - 0.1 * 4.0, abs=1e-9)  # cut off: cross slope x distance from the lower end


def test_rims_restore_the_depth_of_a_polygon_that_ends_inside_them():
    dem, grid, xc = notch_dem("U", 8.0, 2.0, cross_slope=0.0)
    xs, _ = grid.cell_centres()
    lab = np.zeros(dem.shape, np.int32)
    lab[20:220, :] = (np.abs(xs - xc) <= 2.5)[None, :]  # the pool outline at fill depth t ends 1.5 m inside the rims
    polys = polygons_from_labels(lab, grid, 0.5)
    rims = np.zeros(dem.shape, bool)
    rims[:, np.abs(np.abs(xs - xc) - 4.25) < 0.3] = True  # the breakline band over the rims (cells 3.75-4.75 m out)
    _, s_in, _ = measure_sections(lab, polys, dem, dem, grid, 10.0, "line", 2.0, 1.0, 1.0)
    _, s_rim, _ = measure_sections(lab, polys, dem, dem, grid, 10.0, "line", 2.0, 1.0, 1.0, rims=rims, rim_search_m=4.5)
    assert np.median(s_in["depth_m"]) < 1.9  # the pool's edge is already 0.1 m+ down the U's wall
    assert np.median(s_rim["depth_m"]) == pytest.approx(2.0, abs=0.05)
    assert np.median(s_rim["width_m"]) == pytest.approx(np.median(s_in["width_m"]))  # width stays the clipped length
    # the stored line is the clipped section (its length = width); the reference span reaches the rims
    assert np.allclose(s_rim.geometry.length, s_rim["width_m"], atol=1e-6)
    assert (s_rim["reference_length_m"] > s_rim["width_m"] + 2.0).all()


def test_bad_branch_and_rim_settings_are_one_sentence():
    with pytest.raises(InputError, match=r"^polygons.morphometry.branches: must be one of \('all', 'longest'\), got 'tree'$"):
        PolygonParams(branches="tree")
    with pytest.raises(InputError, match=r"^polygons.morphometry.rim_search_m: must be 0 or more, got -1.0$"):
        PolygonParams(rim_search_m=-1.0)
