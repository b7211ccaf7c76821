"""Entry points of the closerange stage: parameters, one-sentence failures, Table 1 and accuracy tables (issue 20)."""

from __future__ import annotations

from datetime import datetime
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

from kitegully import InputError
from kitegully.closerange import CloseRangeParams, closerange_tables, failed_scene_record, photogrammetric_orthophoto
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
           "timings_s": {"total": 60.0}, "sift": "affine (fallback; plain SIFT: 11/36 photos registered)"}
    conf_sfm = {"scene": "scene_06", "confusion": [[90, 5], [5, 100]], "area_auto_m2": 4.1, "area_ref_m2": 4.0}
    conf_dir = {"scene": "scene_06", "confusion": [[95, 1], [1, 103]], "area_auto_m2": 4.2, "area_ref_m2": 4.3}
    t = closerange_tables([rec], [conf_sfm], [conf_dir])
    row = t.table1.iloc[0]
    assert row["paper_images_used"] == 243 and row["paper_marker_error_m"] == 0.04 and np.isnan(row["scale_error_pct"])
    assert t.table1["scene"].iloc[-1] == "all"
    assert row["sift"] == "affine" and t.table1["sift"].iloc[-1] == "affine in 1"
    acc = t.accuracy.set_index("scene")
    assert acc.loc["scene_06", "oa_sfm_pct"] == pytest.approx(95.0)
    assert acc.loc["scene_06", "oa_direct_pct"] == pytest.approx(99.0)
    assert acc.loc["all", "oa_paper_pct"] == 94.3


def test_mismatched_points_are_dropped_and_small_holes_filled():
    from kitegully.closerange.gridding import fill_holes, near_median_surface

    grid = GridSpec(0.0, 1.0, 0.02, 50, 50, "EPSG:32632")
    rng = np.random.default_rng(0)
    xyz = np.column_stack([rng.uniform(0, 1, 20000), rng.uniform(0, 1, 20000), rng.normal(0, 0.005, 20000)])
    xyz[:500, 2] += 2.0  # matched onto the far hillside
    keep = near_median_surface(xyz, grid, 0.1, 0.15)
    assert not keep[:500].any() and keep[500:].mean() > 0.99
    dem = np.zeros((50, 50), np.float32)
    dem[10:12, 10:12] = np.nan  # 4-cell hole
    dem[30:50, 30:50] = np.nan  # 400-cell gap
    ortho = np.full((3, 50, 50), 100, np.uint8)
    dem2, ortho2, filled = fill_holes(dem, ortho, np.ones((50, 50), bool), 100)
    assert filled == 4 and np.isfinite(dem2[10:12, 10:12]).all() and np.isnan(dem2[30:, 30:]).all()


def test_on_scene_failure_key_defaults_to_stop_and_is_checked():
    assert CloseRangeParams().on_scene_failure == "stop"
    assert CloseRangeParams.from_config(SITE["closerange"]).on_scene_failure == "stop"
    assert CloseRangeParams.from_config({"on_scene_failure": "record"}).on_scene_failure == "record"
    with pytest.raises(InputError, match="^closerange.on_scene_failure: 'skip' is not one of stop, record$"):
        CloseRangeParams.from_config({"on_scene_failure": "skip"})
    schema = yaml.safe_load((REPO / "config" / "schema" / "stages" / "closerange.schema.yaml").read_text())
    key = schema["properties"]["on_scene_failure"]
    assert key["enum"] == ["stop", "record"] and key["description"]
    assert "on_scene_failure" not in schema["required"]


def test_a_failed_scene_is_a_row_with_its_sentence_and_left_out_of_the_overall_accuracy():
    def rec(scene, aligned):
        return {"scene": scene, "status": "ok", "images_used": 36, "images_aligned": aligned, "marker_error_m": 0.02,
                "spheres_measured": 4, "scale_error_pct": 1.0, "rule": {"leg_a_m": 1.0, "leg_b_m": 1.01},
                "tie_points": 9000, "dense_points": 2_000_000, "holes_pct": 3.0, "timings_s": {"total": 60.0}}

    reason = "photos: 11 of 36 photos were registered"
    records = [rec("scene_01", 36), failed_scene_record("scene_08", reason), rec("scene_10", 34)]
    conf_sfm = [{"scene": "scene_01", "confusion": [[90, 10], [0, 100]], "area_auto_m2": 4.1, "area_ref_m2": 4.0},
                {"scene": "scene_10", "confusion": [[100, 0], [0, 100]], "area_auto_m2": 4.0, "area_ref_m2": 4.0}]
    conf_dir = [{"scene": s, "confusion": [[100, 0], [0, 100]], "area_auto_m2": 4.0, "area_ref_m2": 4.0}
                for s in ("scene_01", "scene_10")]
    t = closerange_tables(records, conf_sfm, conf_dir)
    acc, t1 = t.accuracy.set_index("scene"), t.table1.set_index("scene")
    assert list(acc.index) == ["scene_01", "scene_08", "scene_10", "all"]
    assert acc.loc["scene_08", "status"] == "failed" and acc.loc["scene_08", "reason"] == reason
    assert np.isnan(acc.loc["scene_08", "oa_sfm_pct"]) and np.isnan(acc.loc["scene_08", "oa_direct_pct"])
    assert acc.loc["all", "oa_sfm_pct"] == pytest.approx(97.5)  # 390 of 400 cells of the two scenes that succeeded
    assert acc.loc["all", "status"] == "2 of 3 scenes" and acc.loc["all", "reason"] == "failed: scene_08"
    assert t1.loc["scene_08", "status"] == "failed" and t1.loc["scene_08", "reason"] == reason
    assert np.isnan(t1.loc["scene_08", "images_aligned"]) and t1.loc["scene_08", "paper_images_used"] == 279
    assert t1.loc["all", "images_aligned"] == pytest.approx(35.0) and t1.loc["all", "status"] == "2 of 3 scenes"
    assert t.table1.columns[1] == "status" and t.accuracy.columns[-1] == "reason"
    assert t1.loc["all", "paper_images_used"] == pytest.approx((613 + 251) / 2)  # the paper over the same scenes


@pytest.mark.parametrize("mode, registered, calls", [
    ("never", [11], [False]), ("always", [36], [True]), ("fallback", [36], [False]),
    ("fallback", [11, 36], [False, True]), ("fallback", [None, 36], [False, True]),
])
def test_affine_sift_where_plain_sift_leaves_photos_out(tmp_path, monkeypatch, mode, registered, calls):
    """closerange.sfm_affine_features: the sfm stage's affine-covariant SIFT and guided matching never, always,
    or redone with them when plain SIFT's model leaves a photo out or builds none (None)."""
    import kitegully.sfm

    seen = []

    def fake_reconstruct(*args):
        p = args[6]
        seen.append(p)
        assert p.estimate_affine_shape == p.domain_size_pooling == p.guided_matching
        assert p.matching.method == "exhaustive" and p.max_num_features == 4096
        n = registered[len(seen) - 1]
        if n is None:
            raise InputError("photos: structure from motion built no model: ...")
        return {"n_images": 36, "n_registered": n}

    def stop(*args):
        raise RuntimeError("stop here")

    monkeypatch.setattr(kitegully.sfm, "reconstruct_model", fake_reconstruct)
    monkeypatch.setattr("kitegully.closerange.stage.read_oriented_photos", stop)
    params = CloseRangeParams.from_config(dict(SITE["closerange"], sfm_affine_features=mode))
    grid = GridSpec(0.0, 5.0, 0.02, 250, 250, "EPSG:32632")
    with pytest.raises(RuntimeError, match="^stop here$"):
        photogrammetric_orthophoto(tmp_path, SURVEY, "markers.csv", grid, SITE["sfm"], params, 1, 1, "scene_08",
                                   tmp_path / "work", _out(tmp_path))
    assert [p.estimate_affine_shape for p in seen] == calls
    with pytest.raises(InputError, match="^closerange.sfm_affine_features: 'sometimes' is not one of never, fallback, always$"):
        CloseRangeParams.from_config({"sfm_affine_features": "sometimes"})
