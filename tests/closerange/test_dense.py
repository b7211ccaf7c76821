"""Pairwise semi-global matching of an oblique photo pair recovers a textured plane (issue 20)."""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from kitegully.closerange.dense import PairMatching, match_pair, pair_geometry_ok, ring_pairs
from kitegully.closerange.model import OrientedPhoto
from kitegully.twin.camera import Camera
from kitegully.twin.polewalk import look_at

CAM = Camera(width=480, height=320, f=320.0, cx=239.5, cy=159.5)


def _photo(name, C, target, tex, roll=0.0):
    R = look_at(C, target, roll)
    t = -R @ C
    v, u = np.mgrid[0:CAM.height, 0:CAM.width].astype(float)
    d = CAM.rays_camera(u, v) @ R  # world directions
    s = -C[2] / d[..., 2]
    X, Y = C[0] + s * d[..., 0], C[1] + s * d[..., 1]
    cell = 0.005  # texture of the plane z = 0 over [-4, 4] m
    r, c = (4.0 - Y) / cell - 0.5, (X + 4.0) / cell - 0.5
    img = np.stack([ndimage.map_coordinates(tex[..., k], [r, c], order=1, mode="nearest") for k in range(3)], axis=-1)
    off = (s <= 0) | (np.abs(X) > 4) | (np.abs(Y) > 4)  # sky and beyond the textured square: uniform, unmatched
    img[off] = (150, 170, 200)
    return OrientedPhoto(name, CAM, R, t), np.clip(img, 0, 255).astype(np.uint8)


def _texture(seed=0):
    rng = np.random.default_rng(seed)
    base = ndimage.gaussian_filter(rng.normal(0, 1, (1600, 1600)), 2.0)
    base = 128 + 60 * base / base.std()
    return np.stack([base, base * 0.9 + 10, base * 0.6], axis=-1)


def test_oblique_pair_recovers_the_plane_to_a_centimetre():
    tex = _texture()
    a, ia = _photo("a", np.array([0.0, -5.0, 3.0]), np.zeros(3), tex)
    b, ib = _photo("b", np.array([0.9, -4.9, 3.1]), np.array([0.1, 0.2, 0.0]), tex, roll=0.03)
    rng = np.random.default_rng(1)
    sparse = np.column_stack([rng.uniform(-2, 2, 400), rng.uniform(-2, 2, 400), np.zeros(400)])
    assert pair_geometry_ok(a, b, PairMatching())
    xyz, rgb = match_pair(ia, ib, a, b, sparse, PairMatching(downscale=1))
    assert len(xyz) > 0.3 * CAM.width * CAM.height
    assert len(rgb) == len(xyz)
    assert abs(np.median(xyz[:, 2])) < 0.01
    assert np.percentile(np.abs(xyz[:, 2]), 90) < 0.05


def test_pair_against_the_tie_points_is_dropped_when_they_disagree():
    tex = _texture()
    a, ia = _photo("a", np.array([0.0, -5.0, 3.0]), np.zeros(3), tex)
    b, ib = _photo("b", np.array([0.9, -4.9, 3.1]), np.array([0.1, 0.2, 0.0]), tex)
    rng = np.random.default_rng(1)
    wrong = np.column_stack([rng.uniform(-2, 2, 400), rng.uniform(-2, 2, 400), np.full(400, 0.8)])  # tie points 0.8 m above
    xyz, _ = match_pair(ia, ib, a, b, wrong, PairMatching(downscale=1, disparity_margin_px=4))
    assert len(xyz) == 0


def test_ring_pairs_skip_a_step_along_the_view():
    photos = []
    for k in range(8):
        ang = 2 * np.pi * k / 8
        C = np.array([5 * np.cos(ang), 5 * np.sin(ang), 3.0])
        if k == 3:
            C = C * np.array([0.8, 0.8, 1.0])  # a step inwards, along the previous view
        photos.append(OrientedPhoto(str(k), CAM, look_at(C, np.zeros(3)), -look_at(C, np.zeros(3)) @ C))
    p = PairMatching(max_convergence_deg=50.0)
    pairs = ring_pairs(photos, p)
    assert 6 <= len(pairs) <= 8
    assert not pair_geometry_ok(photos[4], photos[3], p)  # 4 -> 3 runs along 4's view
    assert (4, 3) not in pairs
    for i, j in pairs:
        assert pair_geometry_ok(photos[i], photos[j], PairMatching(max_convergence_deg=50.0))
