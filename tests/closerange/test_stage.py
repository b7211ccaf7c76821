"""Entry points of the closerange stage: parameters, one-sentence failures, Table 1 and accuracy tables (issue 20)."""

from __future__ import annotations

from datetime import datetime
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

from kitegully import InputError
from kitegully.closerange import CloseRangeParams, closerange_tables, photogrammetric_orthophoto
from kitegully.io.raster import GridSpec
from kitegully.twin.exif import exif_bytes, write_jpeg
from kitegully.twin.polewalk import PoleWalk

REPO = Path(__file__).resolve().parents[2]
SITE = yaml.safe_load((REPO / "config" / "sites" / "kamech_twin.yaml").read_text())
SURVEY = pd.DataFrame({"gcp_id": ["S1", "S2", "S3"], "x": [0.0, 1.0, 0.0], "y": [0.0, 0.0, 1.0], "z": [0.0, 0.0, 0.0]})


def test_site_section_builds_and_bad_values_are_named():
    p = CloseRangeParams.from_config(SITE["closerange"])
    assert p.trim == 0.25 and p.scenes == ("scene_10",) and p.dense.downscale == 2
    assert CloseRangeParams.from_config({"scenes": "all"}).scenes == "all"
    with pytest.raises(InputError, match="closerange.periphery: 'square' is not one of circle, hull"):
        CloseRangeParams.from_config({"periphery": "square"})
    with pytest.raises(InputError, match="closerange.trim"):
        CloseRangeParams.from_config({"trim": 0.5})
    with pytest.raises(InputError, match="block_size_px must be odd"):
        CloseRangeParams.from_config({"dense": {"block_size_px": 4}})
    with pytest.raises(InputError, match="unknown"):
        CloseRangeParams.from_config({"dense": {"window": 5}})


def _out(tmp_path):
    names = dict(model="model", summary="s.json", images="i.csv", image_info="ii.json", orthophoto="o.tif", dem="d.tif",
                 spheres="sp.csv")
    return {k: str(tmp_path / v) for k, v in names.items()}


def test_photos_that_do_not_connect_give_one_sentence(tmp_path):
    cam = PoleWalk(image_width_px=320, image_height_px=240).camera()
    rng = np.random.default_rng(0)
    photos = tmp_path / "photos"
    for i in range(3):  # three unrelated noise pictures: features, but no pair shares verified matches
        img = rng.integers(0, 255, (240, 320, 3), dtype=np.uint8)
        write_jpeg(photos / f"IMG_{i}.JPG", img, exif_bytes(cam, datetime(2015, 7, 14, 10, 0, i)), 95)
    grid = GridSpec(0.0, 5.0, 0.02, 250, 250, "EPSG:32632")
    sfm = dict(SITE["sfm"], threads=1)
    with pytest.raises(InputError) as err:
        photogrammetric_orthophoto(photos, SURVEY, "markers.csv", grid, sfm, CloseRangeParams(), 1, 1, "scene_01",
                                   tmp_path / "work", _out(tmp_path))
    msg = str(err.value)
    assert msg.startswith(f"{photos}: structure from motion built no model")
    assert "\n" not in msg


def test_survey_without_coordinates_is_named(tmp_path):
    grid = GridSpec(0.0, 5.0, 0.02, 250, 250, "EPSG:32632")
    with pytest.raises(InputError, match="^markers.csv: needs columns gcp_id, x, y, z$"):
        photogrammetric_orthophoto(tmp_path, SURVEY.drop(columns="z"), "markers.csv", grid, SITE["sfm"], CloseRangeParams(),
                                   1, 1, "scene_01", tmp_path / "work", _out(tmp_path))


def test_tables_put_the_paper_next_to_ours():
    rec = {"scene": "scene_06", "images_used": 36, "images_aligned": 35, "marker_error_m": 0.02, "spheres_measured": 4,
           "scale_error_pct": None, "rule": None, "tie_points": 9000, "dense_points": 2_000_000, "holes_pct": 3.0,
           "timings_s": {"total": 60.0}}
    conf_sfm = {"scene": "scene_06", "confusion": [[90, 5], [5, 100]], "area_auto_m2": 4.1, "area_ref_m2": 4.0}
    conf_dir = {"scene": "scene_06", "confusion": [[95, 1], [1, 103]], "area_auto_m2": 4.2, "area_ref_m2": 4.3}
    t = closerange_tables([rec], [conf_sfm], [conf_dir])
    row = t.table1.iloc[0]
    assert row["paper_images_used"] == 243 and row["paper_marker_error_m"] == 0.04 and np.isnan(row["scale_error_pct"])
    assert t.table1["scene"].iloc[-1] == "all"
    acc = t.accuracy.set_index("scene")
    assert acc.loc["scene_06", "oa_sfm_pct"] == pytest.approx(95.0)
    assert acc.loc["scene_06", "oa_direct_pct"] == pytest.approx(99.0)
    assert acc.loc["all", "oa_paper_pct"] == 94.3


def test_mismatched_points_are_dropped_and_small_holes_filled():
    from kitegully.closerange.stage import _fill_holes, _near_median_surface

    grid = GridSpec(0.0, 1.0, 0.02, 50, 50, "EPSG:32632")
    rng = np.random.default_rng(0)
    xyz = np.column_stack([rng.uniform(0, 1, 20000), rng.uniform(0, 1, 20000), rng.normal(0, 0.005, 20000)])
    xyz[:500, 2] += 2.0  # matched onto the far hillside
    keep = _near_median_surface(xyz, grid, 0.1, 0.15)
    assert not keep[:500].any() and keep[500:].mean() > 0.99
    dem = np.zeros((50, 50), np.float32)
    dem[10:12, 10:12] = np.nan  # 4-cell hole
    dem[30:50, 30:50] = np.nan  # 400-cell gap
    ortho = np.full((3, 50, 50), 100, np.uint8)
    dem2, ortho2, filled = _fill_holes(dem, ortho, np.ones((50, 50), bool), 100)
    assert filled == 4 and np.isfinite(dem2[10:12, 10:12]).all() and np.isnan(dem2[30:, 30:]).all()
