"""The obia stage's products (kitegully.obia.stage) on constructed masks and tables."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from kitegully import InputError
from kitegully.io.raster import GridSpec, write_raster
from kitegully.obia.stage import classify_scene_products, evaluate_scene, kite_accuracy, summarise_scenes

CRS = "EPSG:32632"
INFO = {"valley": 0.1, "otsu": 0.12, "bimodal": True, "reason": ""}


def _masks():
    truth = np.zeros((10, 10), dtype=np.uint8)
    truth[:, :4] = 1  # 40 eroded cells
    classes = truth.copy()
    classes[0, 4] = 1  # one false eroded
    classes[9, 9] = 255  # a masked marker cell
    otsu = np.zeros_like(truth)
    otsu[9, 9] = 255
    return classes, otsu, truth


def test_evaluate_scene_counts_and_areas():
    classes, otsu, truth = _masks()
    r = evaluate_scene(classes, otsu, truth, 0.5, INFO, "s1")
    # C[mapped, reference]: 58 grass right, 1 mapped eroded wrongly, 40 eroded right; the masked cell left out
    assert r["confusion"] == [[58, 0], [1, 40]]
    assert r["confusion_otsu"] == [[59, 40], [0, 0]]
    assert r["area_ref_m2"] == pytest.approx(40 * 0.25)
    assert r["area_auto_m2"] == pytest.approx(41 * 0.25) and r["area_auto_otsu_m2"] == 0.0
    assert r["eroded_fraction_ref"] == pytest.approx(40 / 99)
    assert r["threshold"] == INFO


def test_summarise_scenes_totals_and_order():
    classes, otsu, truth = _masks()
    a = evaluate_scene(classes, otsu, truth, 0.5, INFO, "s1")
    b = evaluate_scene(truth, truth, truth, 0.5, INFO, "s2")  # perfect, 40 % eroded of 100 cells
    s = summarise_scenes([a, b])
    # sorted by the reference eroded share: s2 40 % < s1 40/99 (the masked cell left out)
    assert list(s.comparison["scene"]) == ["s2", "s1", "all"]
    allrow = s.comparison.iloc[-1]
    assert allrow["oa_valley_pct"] == pytest.approx(100 * (98 + 100) / (99 + 100))
    assert allrow["better"] == "valley"
    assert list(s.areas["scene"]) == ["s1", "s2"] and s.areas["error_m2"].iloc[1] == 0.0
    assert set(s.accuracy["scene"]) == {"s1", "s2", "all"} and len(s.accuracy) == 6


def test_classify_scene_products_checks_inputs():
    grid = GridSpec(0.0, 1.0, 0.02, 50, 50, CRS)
    other = GridSpec(0.0, 2.0, 0.02, 50, 50, CRS)
    paths = {"orthophoto": "o.tif", "dem": "d.tif", "markers": "m.csv"}
    rgb, dem = np.zeros((3, 50, 50), np.uint8), np.zeros((50, 50), np.float32)
    markers = pd.DataFrame({"x": [0.5], "y": [0.5], "radius_m": [0.05]})
    with pytest.raises(InputError, match="^d.tif: DEM grid .* differs from the orthophoto grid"):
        classify_scene_products(rgb, dem, grid, other, markers, {}, "s", paths)
    with pytest.raises(InputError, match=r"^m.csv: missing columns \['radius_m'\]$"):
        classify_scene_products(rgb, dem, grid, grid, markers[["x", "y"]], {}, "s", paths)


def test_kite_accuracy_against_landcover(tmp_path):
    grid = GridSpec(0.0, 10.0, 1.0, 10, 10, CRS)
    lc = np.full((10, 10), 3, dtype=np.uint8)  # grass
    lc[:, :5] = 1  # bare_eroded
    lc[0, :] = 8  # water: excluded
    write_raster(tmp_path / "lc.tif", lc, grid, nodata=255)
    classes = pd.DataFrame({"code": [1, 3, 8], "name": ["bare_eroded", "grass", "water"]})
    bare = (lc == 1).astype(np.uint8)
    bare[5, 7] = 1  # one grass cell mapped bare
    bare[0, :4] = 255  # four water cells left unclassified (not in the confusion matrix either way)
    acc = kite_accuracy(bare, grid, str(tmp_path / "lc.tif"), classes, "classes.csv", ["bare_eroded"], ["water"], "site")
    assert set(acc.accuracy["class"]) == {"vegetated", "bare"}
    assert acc.accuracy["overall_accuracy"].iloc[0] == pytest.approx(100 * 89 / 90)
    assert acc.areas["area_ref_m2"].iloc[0] == pytest.approx(45.0) and acc.areas["area_auto_m2"].iloc[0] == pytest.approx(46.0)
    per = acc.per_class.set_index("landcover_class")
    assert per.loc["water", "reference"] == "excluded" and per.loc["grass", "mapped_bare_pct"] == pytest.approx(100 / 45)
    assert per.loc["water", "area_m2"] == 10.0 and per.loc["water", "not_classified_pct"] == pytest.approx(40.0)
    assert per.loc["grass", "not_classified_pct"] == 0.0
    with pytest.raises(InputError, match=r"^classes.csv: land-cover classes \['rock'\] named in obia.kite_scale"):
        kite_accuracy(bare, grid, str(tmp_path / "lc.tif"), classes, "classes.csv", ["rock"], [], "site")
    with pytest.raises(InputError, match="^classes.csv: needs columns code, name$"):
        kite_accuracy(bare, grid, str(tmp_path / "lc.tif"), classes[["code"]], "classes.csv", [], [], "site")
