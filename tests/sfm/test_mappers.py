"""sfm.mapper: the option validates, and each mapper registers a constructed database.

The database is COLMAP's synthetic scene (``pycolmap.synthesize_dataset``: 14 views of
400 points with exact matches and verified two-view geometries), so no features are
extracted. Its camera's focal length is written 4 % off: a model whose final bundle
adjustment refines the intrinsics recovers the true 1280 px.
"""

from __future__ import annotations

import shutil

import pycolmap
import pytest

from kitegully import InputError
from kitegully.sfm import SfmParams
from kitegully.sfm.reconstruct import _hierarchical_options, _incremental_options, map_model

from .test_stage import PARAMS

TRUE_F = 1280.0


@pytest.fixture(scope="module")
def synthetic_db(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("synthetic")
    (tmp / "images").mkdir()  # the mappers read colours from here; none exist (warnings only)
    o = pycolmap.SyntheticDatasetOptions()
    o.num_rigs, o.num_cameras_per_rig, o.num_frames_per_rig, o.num_points3D = 1, 1, 14, 400
    o.camera_model_id = pycolmap.CameraModelId.RADIAL
    o.camera_params = [TRUE_F, 512.0, 384.0, 0.01, 0.0]
    o.camera_has_prior_focal_length = True
    db = pycolmap.Database.open(str(tmp / "database.db"))
    try:
        pycolmap.set_random_seed(3)
        pycolmap.synthesize_dataset(o, db)
        cam = db.read_camera(1)
        cam.params = [TRUE_F * 1.04, 512.0, 384.0, 0.0, 0.0]  # the prior the mapper starts from
        db.update_camera(cam)
    finally:
        db.close()
    return tmp


@pytest.mark.parametrize("mapper", ["global", "hierarchical", "incremental"])
def test_each_mapper_registers_all_views_and_refines_the_focal_length(synthetic_db, tmp_path, mapper):
    db = tmp_path / "database.db"
    shutil.copy(synthetic_db / "database.db", db)
    rec = map_model(db, synthetic_db / "images", tmp_path / "model", True, 15, 1, 1, mapper=mapper)
    assert rec.num_reg_images() == 14
    assert rec.num_points3D() >= 380
    assert rec.compute_mean_reprojection_error() < 0.01  # exact synthetic matches
    f = float(next(iter(rec.cameras.values())).params[0])
    assert f == pytest.approx(TRUE_F, rel=1e-3)  # from 1331 px: the final BA refined it
    assert (tmp_path / "model" / "cameras.bin").exists() and not (tmp_path / "model_all").exists()


def test_mapper_option_validates():
    assert SfmParams.from_config(PARAMS).mapper == "incremental"  # key left out: the default
    assert SfmParams.from_config({**PARAMS, "mapper": "global"}).mapper == "global"
    with pytest.raises(InputError, match=r"^sfm.mapper: must be one of incremental, global, hierarchical, got 'glomap'$"):
        SfmParams.from_config({**PARAMS, "mapper": "glomap"})


def test_global_ba_growth_validates_and_reaches_colmap():
    assert SfmParams.from_config(PARAMS).global_ba_growth == 1.1  # key left out: COLMAP's own ratio
    assert SfmParams.from_config({**PARAMS, "global_ba_growth": 1.3}).global_ba_growth == 1.3
    with pytest.raises(InputError, match=r"^sfm.global_ba_growth: must be above 1, got 1.0$"):
        SfmParams.from_config({**PARAMS, "global_ba_growth": 1.0})
    inc = _incremental_options(True, 15, 1, 1, 1.3)
    assert (inc.ba_global_frames_ratio, inc.ba_global_points_ratio) == (1.3, 1.3)
    assert _hierarchical_options(True, 15, 1, 2, 1.4).incremental_options.ba_global_frames_ratio == 1.4


def test_sparser_global_adjustments_still_register_all_views_and_refine_f(synthetic_db, tmp_path):
    db = tmp_path / "database.db"
    shutil.copy(synthetic_db / "database.db", db)
    rec = map_model(db, synthetic_db / "images", tmp_path / "model", True, 15, 1, 1, global_ba_growth=2.0)
    assert rec.num_reg_images() == 14
    assert float(next(iter(rec.cameras.values())).params[0]) == pytest.approx(TRUE_F, rel=1e-3)  # the final BA is unchanged


def test_unknown_mapper_is_refused_before_colmap_runs(tmp_path):
    with pytest.raises(InputError, match=r"^sfm.mapper: 'vocab' is not one of incremental, global, hierarchical$"):
        map_model(tmp_path / "none.db", tmp_path, tmp_path / "m", True, 15, 1, 1, mapper="vocab")


@pytest.mark.parametrize("mapper", ["global", "hierarchical", "incremental"])
def test_views_without_matches_give_the_same_no_model_sentence(tmp_path, mapper):
    (tmp_path / "images").mkdir()
    o = pycolmap.SyntheticDatasetOptions()
    o.num_rigs, o.num_cameras_per_rig, o.num_frames_per_rig, o.num_points3D = 1, 1, 4, 50
    db = pycolmap.Database.open(str(tmp_path / "database.db"))
    try:
        pycolmap.synthesize_dataset(o, db)
        db.clear_two_view_geometries()
        db.clear_matches()
    finally:
        db.close()
    with pytest.raises(InputError, match=r"^photos: structure from motion built no model: no pair of the 4 photos shares 15 verified"):
        map_model(tmp_path / "database.db", tmp_path / "images", tmp_path / "m", True, 15, 1, 1, "photos", mapper)
