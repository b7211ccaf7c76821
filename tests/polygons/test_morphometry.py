"""Morphometry: V and U notches of known width, depth and volume recovered within a cell."""

from __future__ import annotations

import numpy as np
import pytest

from kitegully.config import load_yaml
from kitegully.polygons.conditioning import polygons_from_labels
from kitegully.polygons.medial import open_at_edges
from kitegully.polygons.morphometry import measure_sections
from kitegully.polygons.stage import PolygonParams, measure_polygons

from .polygon_synthetic import notch_dem, true_area

WIDTH, DEPTH = 8.0, 2.0


@pytest.mark.parametrize("shape", ["V", "U"])
def test_sections_of_a_known_footprint(shape):
    # level rims (no cross slope), polygon = the notch footprint
    dem, grid, xc = notch_dem(shape, WIDTH, DEPTH, cross_slope=0.0)
    xs, ys = grid.cell_centres()
    lab = np.zeros(dem.shape, np.int32)
    lab[20:220, :] = (np.abs(xs - xc) <= 0.5 * WIDTH)[None, :]  # cell edges half a cell outside the rims
    polys = polygons_from_labels(lab, grid, 0.5)
    axes, sec, morph = measure_sections(lab, polys, dem, dem, grid, 10.0, "lower_end", 2.0, 1.0, 1.0)
    assert len(axes) == 1 and len(sec) >= 8
    inner = sec[(sec["station_m"] > 10) & (sec["station_m"] < axes["length_m"].iloc[0] - 10)]
    assert np.abs(inner["width_m"] - WIDTH).max() <= grid.cell
    assert np.abs(inner["depth_m"] - DEPTH).max() <= 0.01
    a_true = true_area(shape, WIDTH, DEPTH)
    assert inner["area_m2"].median() == pytest.approx(a_true, rel=0.12)
    # volume of the measured reach: area x length of the medial axis
    assert morph["volume_m3"].iloc[0] == pytest.approx(a_true * morph["length_m"].iloc[0], rel=0.12)


@pytest.mark.parametrize("params", ["paper", "site"])
@pytest.mark.parametrize("shape, width_tol_cells", [("V", 1), ("U", 2)])
def test_whole_method_on_a_notch(shape, width_tol_cells, params, repo_root):
    """Breaklines, thalweg, dams, fill and sections on a gully with a headcut in a tilted plane.

    The V's rims are found within a cell. The U (p = 4) is concave just inside its rims, which
    pulls the 9 x 9 convexity band, and with it the breakline skeleton, one cell outwards.
    Depth is measured from the lower rim (paper) or the line between the rims (site), which
    the plane's cross slope lifts above the axis by up to 0.05 x W/2 = 0.2 m.
    """
    cross = 0.05
    dem, grid, xc = notch_dem(shape, WIDTH, DEPTH, cross_slope=cross, head_m=20.0)
    if params == "paper":
        p = PolygonParams(transect_half_length_m=15.0, transect_max_drop_m=0.5, bridge="transects")
    else:  # the default site's settings, with every [I] option on
        p = PolygonParams.from_config(load_yaml(repo_root / "config" / "sites" / "kamech_twin.yaml")["polygons"])
    res = measure_polygons(dem, grid, p)
    assert len(res.polygons[0.5]) == 1
    sec = res.sections
    assert len(sec) >= 6
    if p.terrain_held == "cells":  # only water the dams alone hold t deep: the outline is that water's t-deep edge,
        # below the rim by t at the lower dam and by t + the fall between dams (max_drop) at the upper one;
        # on the V's straight walls that is W t / D to W (t + drop) / D narrower (a U's steep walls lose less)
        lo = WIDTH * (1 - (p.morph_threshold_m + p.transect_max_drop_m) / DEPTH) if shape == "V" else WIDTH - 2 * width_tol_cells * grid.cell
        assert lo - grid.cell <= np.median(sec["width_m"]) <= WIDTH + width_tol_cells * grid.cell
    else:
        assert np.median(np.abs(sec["width_m"] - WIDTH)) <= width_tol_cells * grid.cell + 1e-6
    # the reference lies on a rim, or on the breakline band up to width_tol_cells outside it (site)
    out = width_tol_cells * grid.cell if p.rim_search_m > 0 else 0.0
    assert np.median(np.abs(sec["depth_m"] - DEPTH)) <= cross * (0.5 * WIDTH + out) + 0.02
    length = res.axes["length_m"].sum()
    area = true_area(shape, WIDTH, DEPTH)
    if p.rim_search_m > 0:  # referenced to the rims, which the valley's cross slope lifts: + the valley's own section s W^2 / 4
        area += cross * WIDTH**2 / 4
    assert res.morphometry["volume_m3"].sum() == pytest.approx(area * length, rel=0.1)


@pytest.mark.parametrize("shape", ["V", "U"])
def test_a_gully_that_leaves_the_dem_is_measured_to_the_edge(shape):
    """The notch runs off the south edge 75 m below its head. Without a dam on the edge the sink
    fill drains its last reach over the edge (no pool, no polygon, about a quarter of the volume
    lost); ``survey_edge_dams`` dams the edge between the rims, and the axis runs out through the
    edge instead of forking into the corners of the cut."""
    cross = 0.05
    dem, grid, xc = notch_dem(shape, WIDTH, DEPTH, cross_slope=cross, head_m=20.0)
    true_volume = true_area(shape, WIDTH, DEPTH) * (dem.shape[0] * grid.cell - 20.0)
    vol, south = {}, {}
    for on in (False, True):
        p = PolygonParams(transect_half_length_m=15.0, bridge="transects", reference="line", prolong_axes=True, survey_edge_dams=on)
        res = measure_polygons(dem, grid, p)
        assert len(res.polygons[0.5]) == 1  # no false pool where the gully's head end meets no edge
        rows = np.nonzero(res.labels[0.5].any(axis=1))[0]
        south[on] = dem.shape[0] - 1 - rows.max()  # cells between the polygon and the south edge
        vol[on] = res.morphometry["volume_m3"].sum()
        if on:
            end = min(res.axes.geometry.iloc[0].coords, key=lambda c: c[1])
            assert end[1] == pytest.approx(grid.bounds[1], abs=grid.cell)  # the axis reaches the edge
            assert end[0] == pytest.approx(xc, abs=2 * grid.cell)  # in the channel, not in a corner of the cut
    assert south[False] * grid.cell > 20.0 and vol[False] < 0.85 * vol[True]
    assert south[True] <= 2 and vol[True] == pytest.approx(true_volume, rel=0.1)  # as the whole-method test


def test_open_at_edges_continues_only_a_polygon_that_reaches_the_edge():
    sub = np.zeros((30, 12), bool)
    sub[5:28, 3:9] = True  # ends 2 cells above the window's (and the DEM's) bottom
    same, top, left = open_at_edges(sub, 40, 10, (100, 100), gap=2)
    assert same is sub and (top, left) == (40, 10)  # 40 + 27 = row 67 of 100: far from the edge
    ext, top, left = open_at_edges(sub, 70, 10, (100, 100), gap=2)  # bottom row 97: within 2 cells
    assert (top, left) == (75, 13) and ext.shape[1] == 6
    assert ext.shape[0] > 23 + 2 and ext[-1].all()  # continued past row 99 with the band's full width


def test_a_hole_in_a_polygon_does_not_cut_its_sections_short():
    # A knot of dam cells the closing did not bridge (or a clump standing in the gully) leaves a hole
    # in the pool's polygon. The axis is thinned from the filled mask, so the sections across it span
    # the filled outline too: clipped at the hole, the sections through it lost the width beyond it.
    dem, grid, xc = notch_dem("U", WIDTH, DEPTH, cross_slope=0.0)
    xs, ys = grid.cell_centres()
    lab = np.zeros(dem.shape, np.int32)
    lab[20:220, :] = (np.abs(xs - xc) <= 0.5 * WIDTH)[None, :]
    c = int(np.argmin(np.abs(xs - (xc + 2.0))))
    for r in range(40, 200, 20):  # holes of 2 x 2 cells, 2 m off the axis, every 10 m along it
        lab[r:r + 2, c:c + 2] = 0
    polys = polygons_from_labels(lab, grid, 0.5)
    assert len(polys.geometry.iloc[0].interiors) == 8
    _, sec, _ = measure_sections(lab, polys, dem, dem, grid, 10.0, "lower_end", 2.0, 1.0, 1.0)
    inner = sec[(sec["station_m"] > 10) & (sec["station_m"] < 190)]
    assert np.abs(inner["width_m"] - WIDTH).max() <= grid.cell
    assert inner["area_m2"].min() == pytest.approx(true_area("U", WIDTH, DEPTH), rel=0.12)
