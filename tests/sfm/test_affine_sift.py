"""Affine-covariant SIFT and guided matching: the sfm keys reach pycolmap (issue 20, scene 08)."""

from __future__ import annotations

import copy

import cv2
import numpy as np
import pycolmap
import pytest

from kitegully import InputError
from kitegully.sfm import SfmParams
from kitegully.sfm import reconstruct as rec
from kitegully.sfm.images import list_images, prepare_images

PARAMS = {
    "image_frame": "stored", "max_image_size": 0, "skip_unreadable": False, "jpeg_quality": 95,
    "camera_model": "RADIAL", "default_focal_factor": 1.2, "max_num_features": 500,
    "first_octave": 0, "refine_principal_point": False, "min_num_matches": 15,
    "matching": {
        "method": "exhaustive", "overlap": 10, "exhaustive_max_images": 60, "camera_log": None,
        "log_time_offset_s": 0.0, "log_max_gap_s": 5.0, "gps_sigma_m": 3.0,
        "spatial_max_distance_m": 250.0, "spatial_max_neighbors": 20,
    }, "threads": 1, "deterministic": True,
}


def test_keys_are_optional_booleans():
    p = SfmParams.from_config(PARAMS)
    assert (p.estimate_affine_shape, p.domain_size_pooling, p.guided_matching) == (False, False, False)
    q = SfmParams.from_config(dict(PARAMS, estimate_affine_shape=True, domain_size_pooling=True, guided_matching=True))
    assert (q.estimate_affine_shape, q.domain_size_pooling, q.guided_matching) == (True, True, True)
    with pytest.raises(InputError, match=r"^sfm.guided_matching: must be true or false, got 'yes'$"):
        SfmParams.from_config(dict(PARAMS, guided_matching="yes"))


def test_guided_matching_reaches_the_matcher(monkeypatch):
    seen = {}
    monkeypatch.setattr(rec.pycolmap, "match_exhaustive",
                        lambda db, matching_options, verification_options, device: seen.update(m=copy.copy(matching_options)))
    rec.match_features("unused.db", 5, "exhaustive", 10, 60, 1, guided_matching=True)
    assert seen["m"].guided_matching is True
    rec.match_features("unused.db", 5, "exhaustive", 10, 60, 1)
    assert seen["m"].guided_matching is False


def _shapes(tmp_path, affine: bool) -> np.ndarray:
    """Singular-value ratio of each keypoint's 2x2 shape matrix, extracted by COLMAP with or without affine shapes."""
    rng = np.random.default_rng(2)
    tex = cv2.GaussianBlur(rng.integers(0, 255, (160, 240), dtype=np.uint8), (0, 0), 2.0)
    photos = tmp_path / "photos"
    photos.mkdir(exist_ok=True)
    for k, im in enumerate((tex, tex[:, ::-1].copy())):
        cv2.imwrite(str(photos / f"p{k}.jpg"), cv2.cvtColor(im, cv2.COLOR_GRAY2BGR))
    infos = prepare_images(list_images(photos), tmp_path / f"images{affine}", 0)
    db = tmp_path / f"db{affine}.db"
    rec.extract_features(db, tmp_path / f"images{affine}", infos, "RADIAL", 1.2, 300, 1, 0,
                         estimate_affine_shape=affine, domain_size_pooling=affine)
    d = pycolmap.Database.open(str(db))
    try:
        kp = d.read_keypoints(1)
    finally:
        d.close()
    s = np.linalg.svd(kp[:, 2:6].reshape(-1, 2, 2), compute_uv=False)
    return s[:, 0] / s[:, 1]


def test_affine_shape_reaches_the_extractor(tmp_path):
    # plain SIFT frames are similarities (isotropic); the covariant extractor fits elliptic shapes
    assert np.allclose(_shapes(tmp_path, False), 1.0, atol=1e-3)
    ratios = _shapes(tmp_path, True)
    assert np.median(ratios) > 1.05 and ratios.max() > 1.5
