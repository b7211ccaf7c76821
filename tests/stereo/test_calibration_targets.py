"""Calibration targets rendered as printed discs and located in the photograph (issue 19)."""

import numpy as np
import pytest

from kitegully import InputError
from kitegully.stereo.calibration_targets import (calibration_targets, measure_targets, projected_disc_offset_px, render_calibration_image)
from kitegully.stereo.control_field import ControlField, calibration_field, convergent_poses
from kitegully.stereo.rig import D2H_NOMINAL_F_MM, D2H_PIXEL_MM, paper_cameras
from kitegully.twin.camera import Camera


def _nominal(cam: Camera) -> Camera:
    return Camera(**{**cam.__dict__, "f": D2H_NOMINAL_F_MM / D2H_PIXEL_MM, "cx": (cam.width - 1) / 2, "cy": (cam.height - 1) / 2,
                     "k1": 0.0, "k2": 0.0})


def _subset(field: ControlField, ids) -> ControlField:
    k = [list(field.ids).index(i) for i in ids]
    return ControlField(field.ids[k], field.xyz[k])


def _window(cam, pose, xyz, pad=120):
    uv = cam.project(xyz, pose)
    return (int(uv[:, 0].min()) - pad, int(uv[:, 1].min()) - pad, int(uv[:, 0].max()) + pad, int(uv[:, 1].max()) + pad)


def test_rendered_targets_located_within_0p02_px_of_their_projection():
    cam = paper_cameras()["left"]
    pose = convergent_poses()[1]  # a 27° convergent station: the discs are ellipses
    field = _subset(calibration_field(), ["P07", "P08", "T05", "T06"])
    img = render_calibration_image(cam, pose, calibration_targets(field), 1.0, np.random.default_rng(3), _window(cam, pose, field.xyz))
    m = measure_targets(img, _nominal(cam), pose, field, 0.010, 80.0, "left 8")
    assert list(m.observation.ids) == list(field.ids) and not m.dropped
    err = m.observation.uv - cam.project(field.xyz, pose)
    # [I] 0.02 px: 1 DN noise on a ~200 DN disc gives centroids of ~0.002 px; the ellipse offset is < 0.01 px
    assert np.abs(err).max() < 0.02
    assert np.all(m.sigma_px < 0.01)


def test_projected_disc_offset_matches_first_order_formula():
    cam = paper_cameras()["left"]
    pose = convergent_poses()[0]
    X = np.array([[0.0, 0.0, 0.1]])
    off = projected_disc_offset_px(cam, pose, X, 0.005)
    Z = float(np.linalg.norm(pose.C - X[0]))
    theta = np.arccos(pose.R[2, 2] * -1) if pose.R[2, 2] < 0 else np.arccos(pose.R[2, 2])
    first = cam.f * 0.005**2 * np.sin(theta) * np.cos(theta) / Z**2
    assert 0.002 < np.hypot(*off[0]) < 0.01
    assert np.hypot(*off[0]) == pytest.approx(first, rel=0.3)


def test_target_not_in_rendered_image_is_one_sentence():
    cam = paper_cameras()["left"]
    pose = convergent_poses()[1]
    field = _subset(calibration_field(), ["P07", "P08", "T05", "T06"])
    win = _window(cam, pose, field.xyz[:3])
    uv6 = cam.project(field.xyz[3:], pose)[0]
    img = render_calibration_image(cam, pose, calibration_targets(field), 1.0, np.random.default_rng(3), win)
    img[int(uv6[1]) - 60:int(uv6[1]) + 60, int(uv6[0]) - 60:int(uv6[0]) + 60] = np.nan  # T06 not in the photograph
    with pytest.raises(InputError, match=r"^left 8: calibration target T06 not found within \d+ px of its predicted position"):
        measure_targets(img, _nominal(cam), pose, field, 0.010, 80.0, "left 8")
