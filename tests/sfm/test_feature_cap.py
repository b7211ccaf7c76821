"""The SIFT feature cap applied after COLMAP's extraction (kitegully.sfm.feature_cap)."""

from __future__ import annotations

import sqlite3

import numpy as np
import pycolmap
import pytest
from PIL import Image

from kitegully import InputError
from kitegully.sfm.feature_cap import cap_features, keypoint_scales, select_largest


def _affine(x, y, scale, angle):
    c, s = scale * np.cos(angle), scale * np.sin(angle)
    return [x, y, c, -s, s, c]


def test_scales_from_the_affine_shape():
    kp = np.array([_affine(1, 2, 3.0, 0.4), _affine(5, 6, 0.5, 2.0)], dtype=np.float32)
    assert keypoint_scales(kp) == pytest.approx([3.0, 0.5], rel=1e-6)
    assert keypoint_scales(np.array([[1, 2, 7.0, 0.1]], dtype=np.float32)) == pytest.approx([7.0])


def test_largest_scales_kept_with_their_orientation_duplicates():
    rows = [_affine(10, 10, 1.0, 0.0), _affine(20, 20, 4.0, 0.0), _affine(20, 20, 4.0, 1.5),  # one location, two orientations
            _affine(30, 30, 2.0, 0.0), _affine(40, 40, 8.0, 0.3), _affine(50, 50, 0.7, 0.0)]
    kp = np.array(rows, dtype=np.float32)
    assert select_largest(kp, 3).tolist() == [1, 2, 3, 4]  # scales 8, 4 (twice), 2
    assert select_largest(kp, 1).tolist() == [4]
    assert select_largest(kp, 5).tolist() == list(range(6))  # 5 locations: nothing cut
    assert select_largest(kp[:0], 3).size == 0


@pytest.fixture(scope="module")
def sift_database(tmp_path_factory):
    root = tmp_path_factory.mktemp("cap")
    rng = np.random.default_rng(3)
    img = rng.integers(0, 255, (240, 320)).astype(np.uint8)
    img = np.kron(img[::4, ::4], np.ones((4, 4), np.uint8))  # blocky texture: many blobs at several scales
    (root / "images").mkdir()
    Image.fromarray(np.repeat(img[:, :, None], 3, axis=2)).save(root / "images" / "a.jpg", quality=95)
    ext = pycolmap.FeatureExtractionOptions()
    ext.num_threads = 1
    ext.sift.max_num_features = 100
    ext.sift.first_octave = 0
    db = root / "database.db"
    pycolmap.extract_features(db, root / "images", extraction_options=ext, device=pycolmap.Device.cpu)
    return db


def _read(db):
    con = sqlite3.connect(str(db))
    r, c, b = con.execute("SELECT rows, cols, data FROM keypoints").fetchone()
    dr, dc, db_ = con.execute("SELECT rows, cols, data FROM descriptors").fetchone()
    con.close()
    return np.frombuffer(b, np.float32).reshape(r, c), np.frombuffer(db_, np.uint8).reshape(dr, dc)


def test_colmap_overshoots_and_the_cap_holds(sift_database, tmp_path):
    db = tmp_path / "database.db"
    db.write_bytes(sift_database.read_bytes())
    kp0, d0 = _read(db)
    locations0 = len(np.unique(kp0[:, :2], axis=0))
    assert locations0 > 100  # COLMAP's CPU SIFT keeps whole levels: more than max_num_features
    stats = cap_features(db, 100)
    kp1, d1 = _read(db)
    assert len(np.unique(kp1[:, :2], axis=0)) == 100
    assert stats["images_capped"] == 1 and stats["keypoints_after"] == len(kp1) < stats["keypoints_before"] == len(kp0)
    keep = select_largest(kp0, 100)
    assert np.array_equal(kp1, kp0[keep]) and np.array_equal(d1, d0[keep])  # descriptors stay with their keypoints
    assert keypoint_scales(kp1).min() >= np.sort(keypoint_scales(kp0))[::-1][len(kp1) - 1] - 1e-6
    again = cap_features(db, 100)  # idempotent
    assert again["images_capped"] == 0
    assert pycolmap.Database.open(str(db)).read_keypoints(1).shape[0] == len(kp1)  # COLMAP reads it back


def test_cap_below_one_is_refused(sift_database):
    with pytest.raises(InputError, match="max_num_features must be at least 1"):
        cap_features(sift_database, 0)
