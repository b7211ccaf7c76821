"""Camera model: projection, distortion inversion, rotations and EXIF."""

from __future__ import annotations

from datetime import datetime

import numpy as np
import pytest

from kitegully import InputError
from kitegully.twin.camera import (
    Camera,
    Pose,
    camera_from_config,
    nadir_rotation,
    quaternion_to_rotation,
    rotation_to_quaternion,
)
from kitegully.twin.exif import exif_bytes, focal_35mm, read_exif, write_jpeg

CAM_CFG = dict(
    sensor_width_mm=23.4, sensor_height_mm=15.6, focal_length_mm=18.0, image_width_px=2000,
    image_height_px=1333, principal_point_offset_px=[12.0, -7.0], k1=-0.06, k2=0.02, make="SONY", model="NEX-5N",
)


def test_camera_from_config_focal_and_principal_point():
    cam = camera_from_config(CAM_CFG)
    assert cam.f == pytest.approx(18.0 * 2000 / 23.4)
    assert cam.cx == pytest.approx(999.5 + 12.0)
    assert cam.cy == pytest.approx(666.0 - 7.0)
    # GSD = H p / f: 0.13 m at 500 m with the full 4912 px sensor (METHODS 1.3)
    full = camera_from_config({**CAM_CFG, "image_width_px": 4912, "image_height_px": 3264})
    assert full.gsd(500.0) == pytest.approx(0.132, abs=0.002)


def test_undistort_inverts_distort_and_rays_reproject():
    cam = camera_from_config(CAM_CFG)
    rng = np.random.default_rng(1)
    u = rng.uniform(0, cam.width - 1, 500)
    v = rng.uniform(0, cam.height - 1, 500)
    d = cam.rays_camera(u, v)
    uv = cam.project_camera(d * rng.uniform(5, 500, (500, 1)))
    assert np.abs(uv - np.column_stack([u, v])).max() < 1e-6


def test_nadir_view_geometry():
    cam = Camera(1000, 600, 800.0, 499.5, 299.5)
    C = np.array([100.0, 200.0, 150.0])
    pose = Pose(nadir_rotation(0.0), C)
    uv = cam.project(np.array([[100.0, 200.0, 50.0], [100.0, 210.0, 50.0], [110.0, 200.0, 50.0]]), pose)
    assert uv[0] == pytest.approx([499.5, 299.5])
    assert uv[1, 1] < 299.5 and uv[1, 0] == pytest.approx(499.5)  # north is up at heading 0
    assert uv[2, 0] > 499.5  # east is right
    # heading 90: image top points east
    uv = cam.project(np.array([[110.0, 200.0, 50.0]]), Pose(nadir_rotation(90.0), C))
    assert uv[0, 1] < 299.5 and uv[0, 0] == pytest.approx(499.5)
    # a point behind the camera does not project
    assert np.isnan(cam.project(np.array([[100.0, 200.0, 300.0]]), pose)).all()


def test_quaternion_round_trip():
    for ang in [(0, 0, 0), (37, 4, -3), (200, -10, 7), (359, 90, 0)]:
        R = nadir_rotation(*ang)
        assert np.allclose(quaternion_to_rotation(rotation_to_quaternion(R)), R, atol=1e-12)
        assert np.allclose(R @ R.T, np.eye(3), atol=1e-12)


def test_exif_round_trip(tmp_path):
    cam = camera_from_config(CAM_CFG)
    img = np.zeros((40, 60, 3), dtype=np.uint8)
    when = datetime(2016, 5, 12, 9, 30, 5)
    write_jpeg(tmp_path / "a.jpg", img, exif_bytes(cam, when, 0.002), 90)
    ex = read_exif(tmp_path / "a.jpg")
    assert ex["make"] == "SONY" and ex["model"] == "NEX-5N"
    assert ex["focal_length_mm"] == pytest.approx(18.0)
    assert ex["focal_length_35mm"] == focal_35mm(cam) == 28  # 18 mm × 43.27/28.12
    # focal plane resolution recovers the pixel pitch: SfM gets f_px = f_mm · res
    assert ex["focal_length_mm"] / 10 * ex["focal_plane_x_res_px_per_cm"] == pytest.approx(cam.f, rel=1e-4)
    assert ex["datetime_original"] == "2016:05:12 09:30:05"


def test_read_exif_bad_file(tmp_path):
    p = tmp_path / "x.jpg"
    p.write_bytes(b"not a jpeg")
    with pytest.raises(InputError, match="x.jpg"):
        read_exif(p)
