"""Low-cost survey helpers: NIR photo check, white balance, match counts by pair type, TIN DSM."""

from __future__ import annotations

import sqlite3

import numpy as np
import pytest
from PIL import Image

from kitegully import InputError
from kitegully.lowcost.stage import MAX_IMAGE_ID, check_nir_images, matches_by_pair_type, tin_dsm, white_balance


def test_nir_photo_without_a_red_channel_is_one_sentence(tmp_path):
    Image.fromarray(np.zeros((8, 8, 3), np.uint8)).save(tmp_path / "rgb_000.jpg")
    Image.fromarray(np.zeros((8, 8, 3), np.uint8)).save(tmp_path / "nir_000.jpg")
    check_nir_images(tmp_path)
    Image.fromarray(np.zeros((8, 8), np.uint8)).save(tmp_path / "nir_001.jpg")
    with pytest.raises(InputError, match=r"nir_001\.jpg: NIR photo has no red channel \(mode L, 1 band\)"):
        check_nir_images(tmp_path)


def test_white_balance_returns_the_panel_reflectance_on_the_panel():
    gamma = 2.2
    panel_dn = np.array([240.0, 200.0, 180.0])
    img = np.stack([np.full((2, 2), v, np.uint8) for v in np.rint(panel_dn)])
    img[:, 0, 0] = 0
    out = white_balance(img, panel_dn, 0.99, gamma)
    assert np.isnan(out[:, 0, 0]).all()
    np.testing.assert_allclose(out[:, 1, 1], 0.99, rtol=1e-6)
    half = white_balance(np.rint(panel_dn * 0.5 ** (1 / gamma)).astype(np.uint8)[:, None, None], panel_dn, 1.0, gamma)
    np.testing.assert_allclose(half.ravel(), 0.5, rtol=0.02)                 # linear after the tone curve


def test_matches_are_counted_by_sensor_pair(tmp_path):
    db = tmp_path / "database.db"
    con = sqlite3.connect(db)
    con.execute("CREATE TABLE images (image_id INTEGER, name TEXT)")
    con.execute("CREATE TABLE two_view_geometries (pair_id INTEGER, rows INTEGER)")
    con.executemany("INSERT INTO images VALUES (?, ?)", [(1, "0000_rgb_000.jpg"), (2, "0001_rgb_001.jpg"), (3, "0002_nir_000.jpg")])
    pairs = [(1, 2, 800), (1, 3, 150), (2, 3, 10)]                        # the last one is below the minimum
    con.executemany("INSERT INTO two_view_geometries VALUES (?, ?)", [(a * MAX_IMAGE_ID + b, n) for a, b, n in pairs])
    con.commit()
    con.close()
    names = {"0000_rgb_000.jpg": "rgb_000.jpg", "0001_rgb_001.jpg": "rgb_001.jpg", "0002_nir_000.jpg": "nir_000.jpg"}
    t = matches_by_pair_type(db, names, 15).set_index("pair_type")
    assert t.loc["RGB-RGB", "pairs_matched"] == 1 and t.loc["RGB-RGB", "mean_matches_per_matched_pair"] == 800
    assert t.loc["RGB-NIR", "pairs_tested"] == 2 and t.loc["RGB-NIR", "pairs_matched"] == 1
    assert t.loc["NIR-NIR", "pairs_matched"] == 0
    assert t.loc["RGB-NIR", "paper_mean_matches"] == 188.2


def test_tin_dsm_reproduces_a_plane():
    rng = np.random.default_rng(0)
    xy = rng.uniform(0, 10, (400, 2)) + [290000.0, 6115000.0]
    z = 0.1 * (xy[:, 0] - 290000.0) - 0.05 * (xy[:, 1] - 6115000.0) + 2.0
    dsm, grid = tin_dsm(np.column_stack([xy, z]), 0.5, "EPSG:32756")
    assert dsm.shape == grid.shape
    xs, ys = np.meshgrid(*grid.cell_centres())
    ok = np.isfinite(dsm)
    assert ok.mean() > 0.8
    np.testing.assert_allclose(dsm[ok], (0.1 * (xs - 290000.0) - 0.05 * (ys - 6115000.0) + 2.0)[ok], atol=1e-4)


def _obia_cfg():
    return {"features": {"slope_window_cells": 5}, "seeds": {"bandwidth_cells": 15},
            "growing": {"position_weight": 0.0, "reference": "mean"}, "exg_blur": {"sigma_cells": 1.0, "radius_cells": 2},
            "threshold": {"bins": 256, "min_class_fraction": 0.01, "max_valley_ratio": 0.9, "unimodal_class": "grass"},
            "classification": {"segment_feature": "blurred", "min_area_m2": 0.0, "index": "ndvi", "water_ndvi_below": 0.0}}


def test_bare_soil_params_check_the_tile_size():
    from kitegully.lowcost.stage import BareSoilParams
    p = BareSoilParams.from_config({"tile_cells": 1024, "min_reflectance": 0.01, "obia": _obia_cfg()})
    assert p.obia.index == "ndvi" and p.tile_cells == 1024 and p.min_reflectance == 0.01
    with pytest.raises(InputError, match=r"lowcost.bare_soil.tile_cells: must be at least 4 seed band widths \(60 cells\)"):
        BareSoilParams.from_config({"tile_cells": 40, "min_reflectance": 0.01, "obia": _obia_cfg()})
    with pytest.raises(InputError, match=r"lowcost.bare_soil.min_reflectance: must lie in \[0, 1\), got 1.5"):
        BareSoilParams.from_config({"tile_cells": 1024, "min_reflectance": 1.5, "obia": _obia_cfg()})


def test_bare_soil_maps_are_scored_on_the_land_both_cover(tmp_path):
    from kitegully.io.raster import GridSpec, write_raster
    from kitegully.lowcost.stage import score_bare_soil_maps
    from kitegully.lowcost.twin_site import CLASS_CODES as C
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


def _survey_cfg(**kw):
    cfg = {"gamma": 2.2, "dsm_cell_m": 0.1, "ortho_upsample": 5, "min_track_length": 3, "occlusion_tolerance_m": 0.1,
           "level_to_water": True, "waterline_min_spread_m": 1.0, "dsm_method": "tin"}
    return {**cfg, **kw}


def test_survey_dsm_method_and_dense_section_are_checked():
    from kitegully.lowcost.stage import SurveyParams
    assert SurveyParams.from_config(_survey_cfg()).dense is None
    matching = {"levels": 3, "window_half_cells": 2, "z_step_cells": 0.5, "refine_radius_steps": 3, "max_labels": 96,
                "z_margin_m": 0.5, "p1": 0.02, "p2": 0.12, "sgm_directions": 8, "min_correlation": 0.3, "min_views": 2,
                "min_std_dn": 3.0, "nan_cost": 1.0, "final_passes": 1}
    dense = {"tile_cells": 256, "overlap_cells": 16, "max_cached_images": 28, "matching": matching}
    p = SurveyParams.from_config(_survey_cfg(dsm_method="dense", dense=dense))
    assert p.dense["matching"].levels == 3 and p.dense["tile_cells"] == 256
    with pytest.raises(InputError, match="lowcost.survey.dsm_method: must be tin or dense, got 'pmvs'"):
        SurveyParams.from_config(_survey_cfg(dsm_method="pmvs"))
    with pytest.raises(InputError, match="lowcost.survey.dense: dsm_method dense needs the dense section"):
        SurveyParams.from_config(_survey_cfg(dsm_method="dense"))
    with pytest.raises(InputError, match="lowcost.survey.dense.matching"):
        SurveyParams.from_config(_survey_cfg(dsm_method="dense", dense={**dense, "matching": {"levels": 3}}))


def test_map_bare_soil_masks_unlit_cells_and_maps_by_both_indices(tmp_path):
    from kitegully.io.raster import GridSpec, read_raster, write_raster
    from kitegully.lowcost.stage import map_bare_soil
    n = 120
    grid = GridSpec(290000.0, 6115000.0, 0.02, n, n, "EPSG:32756")
    rows, cols = np.mgrid[0:n, 0:n]
    plants = (rows - 60) ** 2 + (cols - 50) ** 2 <= 30 ** 2
    rng = np.random.default_rng(0)
    rgbn = np.where(plants[None], np.array([0.05, 0.12, 0.04, 0.45])[:, None, None],
                    np.array([0.21, 0.19, 0.17, 0.23])[:, None, None]) * (1 + rng.normal(0, 0.1, (4, n, n)))
    rgbn[:, :10] = 1e-4                                                   # beyond the imaged ground: black
    write_raster(tmp_path / "rgb.tif", rgbn[:3].astype(np.float32), grid)
    write_raster(tmp_path / "nir.tif", rgbn[3:].astype(np.float32), grid)
    write_raster(tmp_path / "dsm.tif", np.ones((n, n), np.float32), grid)
    cfg = {"tile_cells": n, "min_reflectance": 0.01, "obia": _obia_cfg()}
    t = map_bare_soil(tmp_path / "rgb.tif", tmp_path / "nir.tif", tmp_path / "dsm.tif", cfg, tmp_path / "out").set_index("index")
    assert list(t.index) == ["ndvi", "exg"] and (t["dark_cells"] == 10 * n).all()
    assert t.loc["ndvi", "bimodal"] and t.loc["exg", "bimodal"]
    for name in ("ndvi", "exg"):
        m, _ = read_raster(tmp_path / "out" / f"bare_soil_{name}.tif")
        assert np.all(m[:10] == 255)
        inner = ~plants & (rows >= 30) | (plants & ((rows - 60) ** 2 + (cols - 50) ** 2 <= 12 ** 2))
        assert np.mean(m[inner] == np.where(plants, 0, 1)[inner]) > 0.97
    assert not list((tmp_path / "out").glob("tmp*"))                       # the masked mosaic is not left behind
