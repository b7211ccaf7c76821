"""Network validation lengths (Thommeret et al. 2010) and area scores on constructed cases."""

from __future__ import annotations

import numpy as np
import pytest
from shapely import LineString, box

from kitegully.evaluate.network import (
    area_scores,
    footprint,
    network_validation,
    rasterize_polygons,
    validation_geometries,
)
from kitegully.io.raster import GridSpec


def table(df):
    return dict(zip(df["category"], df["length_m"])), dict(zip(df["category"], df["percent"]))


def test_constructed_network_lengths():
    ref = [LineString([(0, 0), (100, 0)])]
    # extracted: the first 80 m, 2 m off, plus a 30 m spur far from the reference
    ext = [LineString([(0, 2), (80, 2)]), LineString([(50, 40), (50, 70)])]
    length, pct = table(network_validation(ref, ext, tolerance_m=5.0))
    # the 5 m buffer around the extracted line ends at x = 85 (round cap)
    # good fit along y=0 from -5..85 → 0..80 + sqrt(5²-2²) = 84.58 m
    good = 80 + np.sqrt(25 - 4)
    assert length["reference"] == pytest.approx(100)
    assert length["good_fit"] == pytest.approx(good, abs=0.05)  # buffer arcs are polygonised
    assert length["false_negative"] == pytest.approx(100 - good, abs=0.05)
    assert length["false_positive"] == pytest.approx(30, abs=1e-9)
    assert pct["good_fit"] + pct["false_negative"] == pytest.approx(100)
    assert pct["false_positive"] == pytest.approx(30)


def test_tolerance_below_offset_gives_no_match():
    ref = [LineString([(0, 0), (100, 0)])]
    ext = [LineString([(0, 3), (100, 3)])]
    length, pct = table(network_validation(ref, ext, tolerance_m=2.0))
    assert length["good_fit"] == 0 and length["false_negative"] == pytest.approx(100)
    assert length["false_positive"] == pytest.approx(100)
    length, _ = table(network_validation(ref, ext, tolerance_m=15.0))
    assert length["good_fit"] == pytest.approx(100) and length["false_positive"] == pytest.approx(0)


def test_domain_clipping_and_empty_extracted():
    ref = [LineString([(0, 0), (100, 0)]), LineString([(200, 0), (300, 0)])]
    length, pct = table(network_validation(ref, [], tolerance_m=5.0, domain=box(-1, -10, 150, 10)))
    assert length["reference"] == pytest.approx(100)
    assert length["good_fit"] == 0 and length["false_positive"] == 0
    assert pct["false_negative"] == pytest.approx(100)
    _, pct = table(network_validation([], [LineString([(0, 0), (1, 0)])], 5.0))
    assert np.isnan(pct["good_fit"])


def test_validation_geometries_add_up():
    ref = [LineString([(0, 0), (100, 0)])]
    ext = [LineString([(0, 1), (60, 1)]), LineString([(0, 50), (10, 50)])]
    g = validation_geometries(ref, ext, 5.0)
    length, _ = table(network_validation(ref, ext, 5.0))
    assert g["good_fit"].length + g["false_negative"].length == pytest.approx(100)
    assert g["false_positive"].length == pytest.approx(length["false_positive"])


def test_area_scores_on_constructed_masks():
    truth = np.zeros((10, 10), dtype=bool)
    truth[2:6, 2:6] = True  # 16 cells
    pred = np.zeros_like(truth)
    pred[4:8, 2:6] = True  # 16 cells, 8 shared
    s = area_scores(pred, truth, 0.5)
    assert s["intersection_m2"] == pytest.approx(8 * 0.25)
    assert s["precision"] == pytest.approx(0.5) and s["recall"] == pytest.approx(0.5)
    assert s["iou"] == pytest.approx(8 / 24)
    assert np.isnan(area_scores(np.zeros_like(truth), np.zeros_like(truth), 1.0)["iou"])


def test_rasterize_polygons_cell_centres():
    grid = GridSpec(0.0, 10.0, 1.0, 10, 10, "EPSG:32632")
    m = rasterize_polygons([box(2, 2, 5, 4)], grid)
    assert m.sum() == 6
    assert m[6:8, 2:5].all()  # rows 6-7 are y 2..4


# --- reference filter: heads within the DEM, catchment (paper Fig. 9b, METHODS.md 1.6) ---
def test_scored_reference_head_outside_dem_only_drops_the_reach_above_the_first_tributary():
    from kitegully.evaluate.network import scored_reference

    main = LineString([(0, 0), (100, 0)])  # head at x = 0, outside the DEM below
    trib = LineString([(50, 40), (50, 1.5)])  # stops 1.5 m short of the main channel
    dem = box(10, -50, 200, 50)
    sc, ns, counts = scored_reference([main, trib], dem, join_m=3.0)
    assert counts["heads"] == 2 and counts["heads_on_dem"] == 1
    assert sc.length == pytest.approx(50 + 38.5)  # main below the junction + tributary
    assert ns.length == pytest.approx(50)  # main above the junction
    assert sc.length + ns.length == pytest.approx(main.length + trib.length)
    # a join distance below the gap: the tributary does not reach the channel
    sc, ns, _ = scored_reference([main, trib], dem, join_m=1.0)
    assert sc.length == pytest.approx(38.5) and ns.length == pytest.approx(100)


def test_scored_reference_sections_and_catchment():
    from kitegully.evaluate.network import scored_reference

    # three sections of one gully sharing end vertices, and a tributary ending at a section node
    a = LineString([(0, 0), (40, 0)])
    b = LineString([(40, 0), (80, 0)])
    c = LineString([(80, 0), (120, 0)])
    t = LineString([(40, 30), (40, 0)])
    dem = box(-5, -50, 200, 50)
    sc, ns, counts = scored_reference([a, b, c, t], dem, join_m=0.5)
    assert counts["heads"] == 2 and counts["heads_on_dem"] == 2
    assert sc.length == pytest.approx(150) and ns.length == 0
    # head of the main gully off the DEM: a is left out, b and c stay (fed by the tributary)
    sc, ns, _ = scored_reference([a, b, c, t], box(20, -50, 200, 50), join_m=0.5)
    assert sc.length == pytest.approx(110) and ns.length == pytest.approx(40)
    # catchment: only x < 100 is scored
    sc, ns, _ = scored_reference([a, b, c, t], dem, join_m=0.5, catchment=box(-10, -60, 100, 60))
    assert sc.length == pytest.approx(130) and ns.length == pytest.approx(20)


def test_unscored_reference_is_no_false_positive():
    from kitegully.evaluate.network import scored_reference

    main = LineString([(0, 0), (100, 0)])
    ext = [LineString([(0, 1), (100, 1)])]  # the whole channel extracted
    sc, ns, _ = scored_reference([main], box(10, -50, 200, 50), join_m=3.0)
    assert sc.is_empty and ns.length == pytest.approx(100)
    length, pct = table(network_validation([sc], ext, 5.0, reference_all=[main]))
    assert length["reference"] == 0 and length["false_positive"] == pytest.approx(0)
    length, _ = table(network_validation([sc], ext, 5.0))
    assert length["false_positive"] == pytest.approx(100)
    g = validation_geometries([sc], ext, 5.0, reference_all=[main])
    assert g["not_scored"].length == pytest.approx(100) and g["false_positive"].length == pytest.approx(0)


def test_footprint_near_lines_clips_like_the_whole_footprint_and_scorer_matches():
    from kitegully.evaluate.network import NetworkScorer

    grid = GridSpec(0.0, 100.0, 0.5, 200, 200, "EPSG:32632")
    yy, xx = np.mgrid[0:200, 0:200]
    valid = ~(((yy - 80) ** 2 + (xx - 90) ** 2 < 400) | ((yy > 150) & (xx < 60)))  # a lake and a missing corner
    ref = [LineString([(5, 95), (45, 60), (60, 20), (95, 3)]), LineString([(80, 90), (47, 58)])]
    ext = [LineString([(6, 93), (44, 62), (58, 22)]), LineString([(20, 20), (30, 40)])]
    whole = footprint(valid, grid)
    near = footprint(valid, grid, near=[*ref, *ext])
    assert near.area < 0.5 * whole.area
    for lines in (ref, ext):
        for ln in lines:
            assert ln.intersection(near).length == pytest.approx(ln.intersection(whole).length, abs=1e-9)
    scorer = NetworkScorer(ref, near)
    for tol in (1.0, 5.0):
        a = network_validation(ref, ext, tol, whole)
        b = scorer.score(ext, tol)
        assert np.allclose(a["length_m"], b["length_m"], atol=1e-9)


# --- the phases of scored_reference -------------------------------------------------------


def test_reference_joins_finds_the_nearest_line_and_ignores_shared_ends():
    from kitegully.evaluate.network import reference_joins

    main = LineString([(0, 0), (100, 0)])
    trib = LineString([(50, 40), (50, 1)])  # ends 1 m from main, 50 m along it
    other = LineString([(120, 30), (100, 0)])  # ends at main's downstream end: not a junction
    joins, splits = reference_joins([main, trib, other], join_m=3.0, near_end=1e-6)
    assert joins == [(1, 0, pytest.approx(50.0))]
    assert splits[0] == [pytest.approx(50.0)] and splits[1] == [] and splits[2] == []
    joins, _ = reference_joins([main, trib, other], join_m=0.5, near_end=1e-6)
    assert joins == []


def test_split_at_junctions_cuts_lines_and_drops_slivers():
    from kitegully.evaluate.network import split_at_junctions

    main = LineString([(0, 0), (100, 0)])
    pieces, piece_of, start_of = split_at_junctions([main], [[30.0, 70.0, 100.0 - 1e-9]], near_end=1e-6)
    assert [p.length for p in pieces] == pytest.approx([30.0, 40.0, 30.0])
    assert list(piece_of[0]) == [0, 1, 2] and list(start_of[0]) == pytest.approx([0.0, 30.0, 70.0])


def test_piece_graph_and_downstream_of():
    from kitegully.evaluate.network import downstream_of, piece_graph

    # line 0 cut into pieces 0, 1; line 1 (piece 2) joins line 0 at 50 m (start of piece 1)
    piece_of = [np.array([0, 1]), np.array([2])]
    start_of = [np.array([0.0, 50.0]), np.array([0.0])]
    down, has_in = piece_graph(piece_of, start_of, [(1, 0, 50.0)], 3, near_end=1e-6)
    assert down == [[1], [], [1]] and list(has_in) == [False, True, False]
    assert list(downstream_of(np.array([2]), down)) == [False, True, True]
    assert list(downstream_of(np.array([0]), down)) == [True, True, False]
    assert not downstream_of(np.array([], dtype=int), down).any()
