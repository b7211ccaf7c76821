"""The control field and its camera stations (:mod:`kitegully.stereo.control_field`)."""

import numpy as np

from kitegully.stereo.control_field import calibration_field, convergent_poses, simulate_observations
from kitegully.stereo.rig import D2H_PIXEL_MM, camera_to_table, paper_cameras


def test_field_is_the_papers():
    f = calibration_field()
    assert len(f.ids) == 32
    assert (f.xyz[:20, 2] > 0).all() and len(np.unique(f.xyz[:20, 2])) == 3
    assert (f.xyz[20:, 2] == 0).all()


def test_convergent_poses_can_place_the_field_in_the_frame_corners():
    cam = paper_cameras()["left"]
    centre = np.array([[0.0, 0.0, 0.1]])  # the aim point
    plain = [cam.project(centre, p)[0] for p in convergent_poses()]
    assert all(np.hypot(u - cam.cx, v - cam.cy) < 30 for u, v in plain)  # aimed at the field centre (< 30 px: distortion, pp)
    f = camera_to_table(cam)["f_mm"] / D2H_PIXEL_MM
    corners = [cam.project(centre, p)[0] for p in convergent_poses(corner_fraction=0.5, frame_px=(cam.width, cam.height, f))]
    rel = np.array([((u - cam.cx) / (cam.width / 2), (v - cam.cy) / (cam.height / 2)) for u, v in corners])
    np.testing.assert_allclose(np.abs(rel), 0.5, atol=0.03)  # half-way to a corner (radial distortion moves it by < 3 %)
    assert len({(np.sign(x), np.sign(y)) for x, y in rel}) == 4  # all four corners
    field = calibration_field()
    obs = simulate_observations(cam, field, convergent_poses(corner_fraction=0.5))
    rmax = np.hypot(cam.width / 2, cam.height / 2)
    assert max(np.hypot(o.uv[:, 0] - cam.cx, o.uv[:, 1] - cam.cy).max() for o in obs) > 0.85 * rmax
