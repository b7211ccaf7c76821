"""Network validation lengths (Thommeret et al. 2010) and area scores on constructed cases."""

from __future__ import annotations

import numpy as np
import pytest
from shapely import LineString, box

from kitegully.evaluate.network import area_scores, network_validation, rasterize_polygons, validation_geometries
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
