"""Image measurements: printed marks located to sub-pixel, SIFT tie points giving the relative orientation, bad input."""

import cv2
import numpy as np
import pytest

from kitegully import InputError
from kitegully.stereo.measure import MarkDesign, PrintedMarks, coplanarity_residuals_px, locate_marks, sift_tie_points
from kitegully.stereo.rectify import rectify_pair, relative_orientation, relative_orientation_from_poses, vertical_disparity
from kitegully.stereo.rig import look_at_pose, paper_cameras, paper_rig
from kitegully.stereo.synth import render_heightfield, soil_texture


def _disc_image(centres, r, shape=(200, 300), noise=1.0, seed=0):
    """White discs (230 DN) on black plates (13 DN) by 8 × 8 supersampling of each pixel's area (not the renderer's ramp)."""
    h, w = shape
    sub = (np.arange(8) + 0.5) / 8 - 0.5
    yy, xx = np.mgrid[0:h, 0:w].astype(float)
    img = np.full(shape, 13.0)
    for cx, cy in centres:
        cover = np.zeros(shape)
        for a in sub:
            for b in sub:
                cover += np.hypot(xx + a - cx, yy + b - cy) <= r
        img += (230.0 - 13.0) * cover / 64
    return (img + np.random.default_rng(seed).normal(0, noise, shape)).astype(np.float32)


def test_mark_centre_recovered_to_sub_pixel_from_a_rough_prediction():
    true = np.array([[80.37, 95.81], [211.62, 104.18]])
    img = _disc_image(true, r=6.0)
    pred = true + np.array([[12.0, -9.0], [-7.0, 10.0]])  # the nominal rig's prediction is tens of px off
    m = locate_marks(img, pred, np.array([6.0, 6.0]), "left")
    err = np.abs(m.uv - true)
    assert err.max() < 0.02  # noise of 1 DN against 217 DN of contrast: a few thousandths of a pixel
    assert (m.sigma_px < 0.01).all() and (m.contrast_dn > 200).all() and (m.noise_dn < 1.5).all()


def test_a_mark_missing_from_the_image_gives_one_sentence():
    img = _disc_image([[80.4, 95.8]], r=6.0)  # only the first mark was printed
    with pytest.raises(InputError, match=r"frame mark 2 not found in the right image within \d+ px of its predicted position "
                                         r"\(212, 104\): the brightest disc there has a contrast of"):
        locate_marks(img, np.array([[80.0, 96.0], [212.0, 104.0]]), np.array([6.0, 6.0]), "right")


def test_printed_marks_rendered_and_located_where_the_camera_projects_them():
    rig = paper_rig(3.0, 0.6)
    marks = PrintedMarks(np.array([[-0.05, -0.04, 0.01], [0.05, 0.04, 0.01], [0.0, 0.06, 0.01]]), MarkDesign(0.010))
    tex = soil_texture(np.random.default_rng(1), (-0.1, -0.1, 0.1, 0.1))
    uv = rig.left.project(marks.xyz, rig.pose_left)
    win = (int(uv[:, 0].min()) - 40, int(uv[:, 1].min()) - 40, int(uv[:, 0].max()) + 40, int(uv[:, 1].max()) + 40)
    img = render_heightfield(rig.left, rig.pose_left, lambda x, y: 0.002 * np.sin(60 * x), tex, iterations=5, noise_dn=1.0,
                             rng=np.random.default_rng(2), window=win, marks=marks)
    r = 0.005 * rig.left.f / 3.0
    m = locate_marks(img, uv + 5.0, np.full(3, r), "left")
    assert np.abs(m.uv - uv).max() < 0.03


def test_sift_tie_points_recover_a_known_relative_orientation():
    H, B = 2.7, 0.8
    rig = paper_rig(H, B)
    tex = soil_texture(np.random.default_rng(3), (-0.2, -0.2, 0.2, 0.2))

    def hills(x, y):  # [I] 3 cm of relief: soil clods plus the box's slope, so the scene is not a plane
        return 0.03 * np.sin(2 * np.pi * x / 0.3) * np.cos(2 * np.pi * y / 0.25) + 0.05 * y

    imgs = []
    for cam, pose in ((rig.left, rig.pose_left), (rig.right, rig.pose_right)):
        uv = cam.project(np.array([[x, y, 0.0] for x in (-0.12, 0.12) for y in (-0.12, 0.12)]), pose)
        win = (int(uv[:, 0].min()), int(uv[:, 1].min()), int(uv[:, 0].max()), int(uv[:, 1].max()))
        imgs.append(render_heightfield(cam, pose, hills, tex, iterations=6, noise_dn=1.0, rng=np.random.default_rng(4), window=win))
    tl, tr = sift_tie_points(*imgs)
    assert len(tl) > 500
    cams = paper_cameras()
    nl, nr = (look_at_pose(np.array([sx, 0.0, H]), np.zeros(3)) for sx in (-B / 2, B / 2))
    R, T, inl = relative_orientation(cams["left"], cams["right"], tl, tr, B, approx=relative_orientation_from_poses(nl, nr))
    R0, T0 = relative_orientation_from_poses(rig.pose_left, rig.pose_right)
    rot_deg = np.degrees(np.linalg.norm(cv2.Rodrigues(R @ R0.T)[0]))
    base_deg = np.degrees(np.arccos(T @ T0 / np.linalg.norm(T) / np.linalg.norm(T0)))
    # the right solution, not a twisted or planar-ambiguity one (those are degrees off); over a 0.24 m patch seen by a
    # 25° lens the rotation about the base-normal axis trades against the base's tilt, so each alone is known to ~0.05° ...
    assert inl.mean() > 0.9 and rot_deg < 0.25 and base_deg < 0.5
    # ... and right where the images observe it: true correspondences of the scene are on one epipolar row after rectification
    P = np.column_stack([np.random.default_rng(5).uniform(-0.11, 0.11, (400, 2)), np.zeros(400)])
    P[:, 2] = hills(P[:, 0], P[:, 1])
    rect = rectify_pair(cams["left"], cams["right"], R, T, (H - 0.3, H + 0.3))
    vp = vertical_disparity(rect, rig.left.project(P, rig.pose_left), rig.right.project(P, rig.pose_right))
    assert np.sqrt(np.mean(vp ** 2)) < 0.05  # measured 0.006 px
    res = coplanarity_residuals_px(cams["left"], cams["right"], R, T, tl[inl], tr[inl])
    assert np.sqrt(np.mean(res ** 2)) < 0.3  # SIFT keypoints on this texture: about a tenth of a pixel


def test_too_few_tie_points_give_one_sentence():
    blank = np.full((300, 400), 120.0, np.float32)
    with pytest.raises(InputError, match=r"tie points: SIFT found 0 keypoints in the left and 0 in the right image; "
                                         r"the relative orientation needs at least 8 matched points"):
        sift_tie_points(blank, blank)
