"""The low-cost survey scored against the twin's truth."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from kitegully import InputError
from kitegully.georef.similarity import Similarity
from kitegully.io.raster import GridSpec, write_raster
from kitegully.lowcost import evaluate_lowcost
from kitegully.lowcost.evaluation import score_bare_soil_maps
from kitegully.lowcost.twin_site import CLASS_CODES as C


def test_bare_soil_maps_are_scored_on_the_land_both_cover(tmp_path):
    grid = GridSpec(0.0, 10.0, 1.0, 4, 2, "EPSG:32756")
    cls = np.array([[C["rock"], C["rock"], C["plants"], C["water"]], [C["wet_rock"], C["algae"], C["plants"], C["water"]]], np.uint8)
    ndvi_map = np.array([[1, 1, 0, 255], [1, 0, 0, 255]], np.uint8)       # perfect, sea masked
    exg_map = np.array([[1, 255, 1, 1], [1, 1, 0, 1]], np.uint8)         # one land cell unmapped, 2 plants cells bare
    write_raster(tmp_path / "bare_soil_ndvi.tif", ndvi_map, grid, nodata=255)
    write_raster(tmp_path / "bare_soil_exg.tif", exg_map, grid, nodata=255)
    t = score_bare_soil_maps(tmp_path, cls, grid, ["rock", "wet_rock"]).set_index("index")
    assert t.loc["ndvi", "cells"] == t.loc["exg", "cells"] == 5             # land mapped by both
    assert t.loc["ndvi", "overall_accuracy"] == 1.0
    assert t.loc["exg", "overall_accuracy"] == pytest.approx(3 / 5)
    assert t.loc["exg", "bare_producers_accuracy"] == 1.0
    assert t.loc["exg", "bare_users_accuracy"] == pytest.approx(2 / 4)
    assert t.loc["exg", "land_cells_unmapped"] == 1 and t.loc["ndvi", "land_cells_unmapped"] == 0
    assert t.loc["exg", "water_mapped_bare_pct"] == 100.0 and np.isnan(t.loc["ndvi", "water_mapped_bare_pct"])
    with pytest.raises(InputError, match=r"lowcost.evaluation.bare_classes: unknown cover classes \['sand'\]"):
        score_bare_soil_maps(tmp_path, cls, grid, ["sand"])


def _scene(tmp_path):
    """A survey folder and a truth folder on one 0.1 m grid: rock (bare) west, plants east, sea at the east edge."""
    survey, truth = tmp_path / "survey", tmp_path / "truth"
    survey.mkdir()
    truth.mkdir()
    n_rows, n_cols = 40, 60
    grid = GridSpec(290000.0, 6115004.0, 0.1, n_cols, n_rows, "EPSG:32756")
    cls = np.full((n_rows, n_cols), C["rock"], np.uint8)
    cls[:, 30:] = C["plants"]
    cls[:, 54:] = C["water"]
    write_raster(truth / "classes.tif", cls, grid, nodata=0)
    pd.DataFrame({"class": list(C), "ndvi_camera": [-0.3, 0.02, 0.05, 0.3, 0.6],
                  "ndvi_band": [-0.35, 0.03, 0.06, 0.4, 0.7]}).to_csv(truth / "classes.csv", index=False)
    xs, ys = np.meshgrid(*grid.cell_centres())
    true_dsm = (0.05 * (xs - 290000.0) + 1.0).astype(np.float32)
    write_raster(truth / "dsm.tif", true_dsm, grid)
    rng = np.random.default_rng(0)
    # the survey's DSM: 5 cm high with 2 cm of noise
    write_raster(survey / "dsm.tif", (true_dsm + 0.05 + rng.normal(0, 0.02, true_dsm.shape)).astype(np.float32), grid)
    cover_ndvi = {C["rock"]: 0.05, C["plants"]: 0.6, C["water"]: -0.3}
    cover_exg = {C["rock"]: -0.02, C["plants"]: 0.2, C["water"]: 0.0}
    nd = np.vectorize(cover_ndvi.get)(cls) + rng.normal(0, 0.01, cls.shape)
    ex = np.vectorize(cover_exg.get)(cls) + rng.normal(0, 0.01, cls.shape)
    write_raster(survey / "ndvi.tif", nd.astype(np.float32), grid)
    write_raster(survey / "exg.tif", ex.astype(np.float32), grid)
    bare = np.where(cls == C["rock"], 1, 0).astype(np.uint8)
    write_raster(survey / "bare_soil_ndvi.tif", np.where(cls == C["water"], 255, bare).astype(np.uint8), grid, nodata=255)
    exg_map = bare.copy()
    exg_map[:, 30:35] = 1                                                   # five columns of plants mapped bare
    write_raster(survey / "bare_soil_exg.tif", exg_map, grid, nodata=255)
    targets = {"t1": [290001.0, 6115001.0, 1.05], "t2": [290004.0, 6115003.0, 1.2], "t3": [290005.5, 6115001.5, 1.275]}
    pd.DataFrame([{"target": k, "x_m": v[0], "y_m": v[1], "z_m": v[2]} for k, v in targets.items()]).to_csv(
        truth / "targets.csv", index=False)
    identity = Similarity(1.0, np.eye(3), np.zeros(3)).as_dict()
    moved = lambda dz: {k: [v[0], v[1], v[2] + dz] for k, v in targets.items()}  # noqa: E731
    (survey / "georef.json").write_text(json.dumps({
        "products": "tape_horn_levelled", "tape_horn_levelled": identity, "similarity_rtk": identity,
        "targets_tape_horn_tide": moved(0.5), "targets_tape_horn_levelled": moved(0.1), "targets_similarity_rtk": moved(0.0)}))
    return survey, truth


def test_evaluate_lowcost_scores_a_constructed_survey(tmp_path):
    survey, truth = _scene(tmp_path)
    out = tmp_path / "evaluation"
    res = evaluate_lowcost(survey, truth, {"patch_px": 5, "patches_per_class": 10, "bare_classes": ["rock"]}, 3, out)
    assert res["dsm_median_error_m"] == pytest.approx(0.05, abs=0.005)
    assert res["dsm_nmad_m"] == pytest.approx(0.02, abs=0.003)
    assert res["bare_soil_obia_overall_accuracy"]["ndvi"] == 1.0
    assert res["bare_soil_obia_overall_accuracy"]["exg"] == pytest.approx(1 - 5 * 40 / (54 * 40), rel=1e-9)
    by_class = pd.read_csv(out / "ndvi_by_class.csv").set_index("class")
    assert set(by_class.index) == {"rock", "plants", "water"}
    assert by_class.loc["plants", "error"] == pytest.approx(0.0, abs=0.01)  # the mosaic's NDVI is the camera's
    ind = pd.read_csv(out / "bare_ground_indicators.csv").set_index("indicator")
    # two classes 0.55 apart: Otsu separates them (its threshold sits in the flat gap, near the lower class's tail)
    assert (ind["overall_accuracy"] > 0.995).all() and (ind["cells"] == 54 * 40).all()
    geo = pd.read_csv(out / "georef_truth.csv").set_index("method")
    assert geo.loc["tape_horn_gps + tide shift (paper)", "mean_vertical_error_m"] == pytest.approx(0.5)
    assert geo.loc["tape_horn_gps + waterline levelled + tide", "mean_vertical_error_m"] == pytest.approx(0.1)
    assert geo.loc["similarity_rtk", "mean_3d_error_m"] == pytest.approx(0.0, abs=1e-9)
    dsm = pd.read_csv(out / "dsm_truth.csv")
    assert list(dsm["file"]) == ["dsm.tif"]                                 # no TIN or dense DSM written: only the product
    assert dsm["rtk_frame_median_error_m"].iloc[0] == pytest.approx(0.05, abs=0.005)
