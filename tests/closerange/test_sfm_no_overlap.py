"""Close-range photos that do not connect give one clear sentence from the sfm stage (issue 20)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from kitegully import InputError
from kitegully.seeds import rng_for
from kitegully.sfm.stage import SfmParams, reconstruct_model
from kitegully.twin.camera import Pose
from kitegully.twin.closerange import generate_scene, scene_origin
from kitegully.twin.exif import exif_bytes, write_jpeg
from kitegully.twin.polewalk import PoleWalk, look_at, photograph_walk, prepare_pole_scene
from kitegully.twin.render import surface_height

REPO = Path(__file__).resolve().parents[2]


def test_pole_photos_of_separate_spots_name_the_folder_and_the_reason(tmp_path):
    cfg = yaml.safe_load((REPO / "config" / "sites" / "tiny_twin.yaml").read_text())
    p = cfg["obia"]["scenes"]
    sc = generate_scene("scene_01", p, p["list"][0], 1, "EPSG:32632", scene_origin(0, p))
    ps = prepare_pole_scene(sc, 0.10, False, rng_for(1, "test", "rule"))
    walk = PoleWalk(n_images=3, image_width_px=600, image_height_px=400, pole_height_m=1.0)
    # three near-nadir views 1 m above three corners of the 6 m scene: footprints ~1.5 m, 4 m apart
    g = sc.grid
    spots = np.array([[g.x0 + 1.0, g.y0 - 1.0], [g.x0 + 5.0, g.y0 - 1.0], [g.x0 + 3.0, g.y0 - 5.0]])
    z = surface_height(ps.render, spots[:, 0], spots[:, 1])
    poses = [Pose(look_at(np.r_[s + 0.05, zz + 1.0], np.r_[s, zz]), np.r_[s + 0.05, zz + 1.0]) for s, zz in zip(spots, z)]
    photos = tmp_path / "scene_photos"
    cam = walk.camera()
    from datetime import datetime

    for i, img in photograph_walk(ps, walk, poses, rng_for(1, "test", "photos")):
        write_jpeg(photos / f"IMG_{i}.JPG", img, exif_bytes(cam, datetime(2015, 7, 14, 10, 0, i)), 95)
    s = dict(cfg["sfm"], first_octave=0, threads=1, max_num_features=2048)
    s["matching"] = dict(s["matching"], camera_log=None, method="exhaustive")
    with pytest.raises(InputError) as err:
        reconstruct_model(photos, tmp_path / "work", tmp_path / "model", tmp_path / "s.json", tmp_path / "i.csv",
                          tmp_path / "ii.json", SfmParams.from_config(s), 1, 1)
    msg = str(err.value)
    assert msg.startswith(f"{photos}: structure from motion built no model: no pair of the 3 photos shares 15 verified feature matches")
    assert "\n" not in msg and str(tmp_path / "work") not in msg
