"""benchmarks/sfm_mappers.py: the block-shape check against the true camera centres."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pycolmap
import pytest
from scipy.spatial.transform import Rotation

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "benchmarks"))

import sfm_mappers  # noqa: E402
from kitegully import InputError  # noqa: E402


@pytest.fixture()
def model(tmp_path):
    o = pycolmap.SyntheticDatasetOptions()
    o.num_rigs, o.num_cameras_per_rig, o.num_frames_per_rig, o.num_points3D = 1, 1, 10, 100
    pycolmap.set_random_seed(5)
    return pycolmap.synthesize_dataset(o)


def _truth(rec, tmp_path, shift_one_m: float = 0.0) -> Path:
    """The model's camera centres in a 'world' frame: scaled, rotated and moved (one image displaced)."""
    names = [im.name for im in rec.images.values()]
    c = np.array([im.projection_center() for im in rec.images.values()])
    w = 40.0 * Rotation.from_euler("zyx", [30, 5, -8], degrees=True).apply(c) + [500_000.0, 4_000_000.0, 300.0]
    w[3, 2] += shift_one_m
    path = tmp_path / "poses.csv"
    pd.DataFrame({"image": [Path(n).stem + ".jpg" for n in names], "x_m": w[:, 0], "y_m": w[:, 1], "z_m": w[:, 2]}
                 ).to_csv(path, index=False)
    return path


def test_a_similar_block_has_no_shape_error(model, tmp_path):
    row = sfm_mappers.shape_against_truth(model, _truth(model, tmp_path))
    assert row["n_truth_matched"] == 10  # matched by file stem: the prepared copies' suffix may differ
    assert row["shape_rms_m"] < 1e-3 and row["shape_max_m"] < 1e-3


def test_a_displaced_camera_shows_as_shape_error(model, tmp_path):
    row = sfm_mappers.shape_against_truth(model, _truth(model, tmp_path, shift_one_m=2.0))
    assert 0.5 < row["shape_max_m"] < 2.0  # the similarity spreads part of it over the others
    assert 0.1 < row["shape_rms_m"] < row["shape_max_m"]


def test_prepared_copy_names_are_mapped_to_the_photos(model, tmp_path):
    poses = _truth(model, tmp_path)
    renamed = {f"{k:04d}_{Path(im.name).stem}.jpg": im.name for k, im in enumerate(model.images.values())}
    for im, new in zip(model.images.values(), renamed):
        im.name = new
    with pytest.raises(InputError, match="at least 3 points, got 0"):  # the copies' names alone match no photo
        sfm_mappers.shape_against_truth(model, poses)
    row = sfm_mappers.shape_against_truth(model, poses, renamed)
    assert row["n_truth_matched"] == 10 and row["shape_rms_m"] < 1e-3
