"""SfM's "no model" error names the user's photo folder and gives COLMAP's reason."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from kitegully import InputError
from kitegully.sfm.images import list_images, prepare_images
from kitegully.sfm.reconstruct import extract_features, match_features, why_no_model
from kitegully.sfm.stage import SfmParams, reconstruct_model

REPO = Path(__file__).resolve().parents[2]


def _params(size):
    p = yaml.safe_load((REPO / "config" / "sites" / "boruszyn_kap.yaml").read_text())["sfm"]
    p["max_image_size"] = size
    return p


def test_photos_without_common_features_name_the_user_folder(tmp_path):
    photos = tmp_path / "my_photos"
    photos.mkdir()
    rng = np.random.default_rng(1)
    for k in range(3):
        cv2.imwrite(str(photos / f"p{k}.jpg"), rng.integers(0, 255, (150, 200, 3), dtype=np.uint8))
    work = tmp_path / "results" / "sfm" / "work"
    with pytest.raises(InputError) as err:
        reconstruct_model(photos, work, tmp_path / "m", tmp_path / "s.json", tmp_path / "i.csv", tmp_path / "ii.json", SfmParams.from_config(_params(200)), 1, 1)
    msg = str(err.value)
    assert msg.startswith(f"{photos}: structure from motion built no model: no pair of the 3 photos shares 15 verified feature matches")
    assert str(work) not in msg


def test_photos_from_one_spot_are_diagnosed_as_no_baseline(tmp_path):
    # three views of one textured plane turned about the camera centre: pure rotation
    rng = np.random.default_rng(2)
    tex = cv2.GaussianBlur(rng.integers(0, 255, (450, 600), dtype=np.uint8), (0, 0), 2.0)
    tex = cv2.cvtColor(cv2.equalizeHist(tex), cv2.COLOR_GRAY2BGR)
    K = np.array([[550.0, 0, 300], [0, 550.0, 225], [0, 0, 1]])
    photos = tmp_path / "spot"
    photos.mkdir()
    for k, a in enumerate((0.0, 3.0, 6.0)):
        H = K @ Rotation.from_euler("yx", [a, a / 2], degrees=True).as_matrix() @ np.linalg.inv(K)
        cv2.imwrite(str(photos / f"r{k}.jpg"), cv2.warpPerspective(tex, H, (600, 450)))
    params = _params(600)
    infos = prepare_images(list_images(photos), tmp_path / "images", 600)
    db = tmp_path / "database.db"
    extract_features(db, tmp_path / "images", infos, params["camera_model"], params["default_focal_factor"],
                     params["max_num_features"], 1, params["first_octave"])
    match_features(db, len(infos), "exhaustive", 10, 60, 1)
    assert why_no_model(db, 15).startswith("all 3 overlapping photo pair(s) were taken from one spot (pure camera rotation: no baseline)")


def test_two_cameras_get_one_camera_group_each(tmp_path):
    import piexif

    photos = tmp_path / "mixed"
    photos.mkdir()
    rng = np.random.default_rng(3)
    for k in range(4):
        model = b"Canon PowerShot A3300 IS" if k < 2 else b"Canon EOS 5D"
        exif = piexif.dump({"0th": {piexif.ImageIFD.Make: b"Canon", piexif.ImageIFD.Model: model}, "Exif": {}, "GPS": {}, "1st": {}})
        from PIL import Image

        Image.fromarray(rng.integers(0, 255, (120, 160, 3), dtype=np.uint8)).save(photos / f"p{k}.jpg", exif=exif)
    infos = prepare_images(list_images(photos), tmp_path / "images", 160)
    assert sorted({i.camera for i in infos}) == ["Canon EOS 5D", "Canon PowerShot A3300 IS"]
    params = _params(160)
    db = tmp_path / "database.db"
    extract_features(db, tmp_path / "images", infos, params["camera_model"], params["default_focal_factor"],
                     params["max_num_features"], 1, params["first_octave"])
    import pycolmap

    d = pycolmap.Database.open(str(db))
    try:
        cams = {im.name: im.camera_id for im in d.read_all_images()}
    finally:
        d.close()
    by_cam = {i.camera: {cams[j.sfm_name] for j in infos if j.camera == i.camera} for i in infos}
    assert all(len(v) == 1 for v in by_cam.values()) and len(set().union(*by_cam.values())) == 2
