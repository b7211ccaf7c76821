"""Dense points of a close-range ring of photos by pairwise semi-global matching.

PhotoScan's dense cloud (001) is replaced by OpenCV's semi-global block matching
(Hirschmüller 2008, ``cv2.StereoSGBM``) on neighbouring photos of the walk: each photo is
paired with the next one around the ring (camera centres sorted by azimuth about their
centroid), the pair is rectified with the self-calibrated intrinsics and the relative pose
from SfM, matched, and every disparity is triangulated and coloured from the first photo.
The disparity search range of a pair follows from the sparse SfM points that project
into both photos (their 1st–99th percentile disparity, widened by a margin), so it adapts
to each pair's baseline and depth.  Points are returned in the model frame.

Defects this brings, as in a real SfM orthophoto: no points where one photo sees what the
other does not (behind clods and scarps, at the image border), few in deep shadow and on
uniform soil, smeared heights across scarps (block matching averages over its window).

Cost per pair: O(W·H·disparities) for SGBM at the matching scale; memory O(W·H·disparities)
bytes (int16 cost volume per row path).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import cv2
import numpy as np

from kitegully.closerange.model import OrientedPhoto

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class PairMatching:
    """Semi-global matching of one photo pair.

    Attributes
    ----------
    downscale : int
        Photos are matched at 1/downscale of their size. [I] 2 (PhotoScan's "medium"):
        6 mm pixels at 4 m become 12 mm, still 2–3 points per 2 cm cell per pair.
    block_size_px : int
        SGBM window (odd). [I] 5 px at the matching scale (6 cm on the ground): larger
        smooths scarps, smaller adds noise on grass.
    uniqueness_pct : int
        Best cost must beat the second best by this share.
    speckle_window_px : int
        Disconnected disparity blobs smaller than this are removed.
    disparity_margin_px : float
        Added to both ends of the disparity range seen in the sparse points.
    min_texture_dn : float
        Pixels whose grey values vary less than this (SD over the block, DN) are not
        matched. [I] 2 DN, twice the photos' read noise: sky and blown-out soil.
    max_tie_disagreement_px : float
        A pair whose disparities disagree with the SfM tie points seen in both photos by
        more than this (median, px at the matching scale) is left out: its rectification or
        disparity range failed. [I] 1 px: the tie points reproject to ~0.4 px.
    min_baseline_angle_deg : float
        Smallest angle between the baseline and the first photo's optical axis. [I] 60°:
        a baseline along the view (the photographer stepping inwards) puts the epipole
        near the image and rectification stretches it.
    max_convergence_deg : float
        Largest angle between the two optical axes. [I] 25°: beyond it the two views of
        a grass tuft differ too much for block matching.
    max_partner_steps : int
        Partners tried for each photo, going on around the ring. [I] 3 (30° of the ring
        at 36 photos).
    """

    downscale: int = 2
    block_size_px: int = 5
    uniqueness_pct: int = 10
    speckle_window_px: int = 100
    disparity_margin_px: float = 16.0
    max_tie_disagreement_px: float = 1.0
    min_texture_dn: float = 2.0
    min_baseline_angle_deg: float = 60.0
    max_convergence_deg: float = 25.0
    max_partner_steps: int = 3


def ring_order(centres: np.ndarray) -> np.ndarray:
    """Indices of ``centres`` (M, 2) sorted by azimuth about their centroid (the walked ring)."""
    c = np.asarray(centres, float)
    return np.argsort(np.arctan2(c[:, 1] - c[:, 1].mean(), c[:, 0] - c[:, 0].mean()))


def pair_geometry_ok(a: OrientedPhoto, b: OrientedPhoto, p: "PairMatching") -> bool:
    """A stereo pair worth rectifying: baseline across the view (not along it), axes not too convergent.

    Parameters
    ----------
    a, b : OrientedPhoto
        First and second photo of the pair (model frame).
    p : PairMatching
        Matching settings; reads ``min_baseline_angle_deg`` and ``max_convergence_deg``.

    Returns
    -------
    bool
        True if the baseline makes at least ``min_baseline_angle_deg`` with ``a``'s optical axis and the two axes
        converge by at most ``max_convergence_deg``; False for coincident centres.
    """
    base = b.centre - a.centre
    nb = np.linalg.norm(base)
    if nb <= 0:
        return False
    across = np.degrees(np.arccos(min(abs(base @ a.R[2]) / nb, 1.0)))
    converge = np.degrees(np.arccos(np.clip(a.R[2] @ b.R[2], -1, 1)))
    return across >= p.min_baseline_angle_deg and converge <= p.max_convergence_deg


def ring_pairs(photos: list[OrientedPhoto], p: "PairMatching") -> list[tuple[int, int]]:
    """For each photo, the nearest following photo around the ring (up to ``max_partner_steps``) with a good pair geometry."""
    centres = np.array([ph.centre for ph in photos])
    if len(centres) < 2:
        return []
    cc = centres - centres.mean(axis=0)
    _, _, Vt = np.linalg.svd(cc, full_matrices=False)
    order = ring_order(cc @ Vt[:2].T)  # ring in the best-fit plane of the camera centres
    n = len(order)
    pairs = []
    for k in range(n):
        for step in range(1, min(p.max_partner_steps, n - 1) + 1):
            i, j = int(order[k]), int(order[(k + step) % n])
            if pair_geometry_ok(photos[i], photos[j], p):
                pairs.append((i, j))
                break
    return pairs


def _scaled(cam, s: int):
    K = np.array([[cam.f / s, 0, (cam.cx + 0.5) / s - 0.5], [0, cam.f / s, (cam.cy + 0.5) / s - 0.5], [0, 0, 1.0]])
    return K, np.array([cam.k1, cam.k2, 0.0, 0.0])


def match_pair(
    img_a: np.ndarray, img_b: np.ndarray, a: OrientedPhoto, b: OrientedPhoto, sparse_xyz: np.ndarray, p: PairMatching
) -> tuple[np.ndarray, np.ndarray]:
    """Dense points (model frame) and their colours from one photo pair.

    Parameters
    ----------
    img_a, img_b : ndarray (H, W, 3) uint8
        RGB photos of ``a`` and ``b`` at full size.
    a, b : OrientedPhoto
        Orientations of the two photos (model frame).
    sparse_xyz : ndarray (N, 3)
        Sparse SfM points (model frame); those in front of both photos set the disparity range and check the matches.
    p : PairMatching
        Matching settings.

    Returns
    -------
    xyz : (N, 3) float64, colours : (N, 3) uint8 (from ``img_a``)
    """
    s = p.downscale
    h, w = img_a.shape[0] // s, img_a.shape[1] // s
    A = cv2.resize(img_a, (w, h), interpolation=cv2.INTER_AREA) if s > 1 else img_a
    B = cv2.resize(img_b, (w, h), interpolation=cv2.INTER_AREA) if s > 1 else img_b
    Ka, da = _scaled(a.camera, s)
    Kb, db = _scaled(b.camera, s)
    R = b.R @ a.R.T  # a-camera → b-camera
    t = b.t - R @ a.t
    R1, R2, P1, P2, Q, _, _ = cv2.stereoRectify(Ka, da, Kb, db, (w, h), R, t.reshape(3, 1), flags=cv2.CALIB_ZERO_DISPARITY, alpha=-1)
    # disparity range from the sparse points seen in front of both photos
    Xa = sparse_xyz @ a.R.T + a.t
    Xb = sparse_xyz @ b.R.T + b.t
    front = (Xa[:, 2] > 0) & (Xb[:, 2] > 0)
    empty = (np.zeros((0, 3)), np.zeros((0, 3), np.uint8))
    zoom = P1[0, 0] / Ka[0, 0]
    if not 0.6 <= zoom <= 1.6:  # rectification warps the photos too much to keep their resolution
        log.info("pair %s-%s left out: rectification zooms by %.2f", a.name, b.name, zoom)
        return empty
    if front.sum() < 20:
        log.info("pair %s-%s left out: %d tie points in front of both", a.name, b.name, front.sum())
        return empty
    ra = Xa[front] @ R1.T
    rb = Xb[front] @ R2.T
    ua = P1[0, 0] * ra[:, 0] / ra[:, 2] + P1[0, 2]
    ub = P2[0, 0] * rb[:, 0] / rb[:, 2] + P2[0, 2]
    va = P1[1, 1] * ra[:, 1] / ra[:, 2] + P1[1, 2]
    inside = (ua >= 0) & (ua < w) & (va >= 0) & (va < h)
    if inside.sum() < 20:
        log.info("pair %s-%s left out: %d tie points inside the rectified image", a.name, b.name, inside.sum())
        return empty
    log.debug("pair %s-%s: %d tie points in front, %d inside; P2 %s", a.name, b.name, front.sum(), inside.sum(), P2[:2, 3])
    disp = (ua - ub)[inside]
    lo, hi = np.percentile(disp, [1, 99])
    horizontal = abs(P2[0, 3]) >= abs(P2[1, 3])
    if not horizontal:  # vertical rectification (the baseline runs along the image columns)
        log.info("pair %s-%s left out: vertical baseline", a.name, b.name)
        return empty
    min_d = int(np.floor(lo - p.disparity_margin_px))
    num = int(np.ceil((hi - lo + 2 * p.disparity_margin_px) / 16.0)) * 16
    num = max(16, min(num, 512))
    ma1, ma2 = cv2.initUndistortRectifyMap(Ka, da, R1, P1, (w, h), cv2.CV_32FC1)
    mb1, mb2 = cv2.initUndistortRectifyMap(Kb, db, R2, P2, (w, h), cv2.CV_32FC1)
    ra_img = cv2.remap(A, ma1, ma2, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    rb_img = cv2.remap(B, mb1, mb2, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    valid_a = cv2.remap(np.ones((h, w), np.uint8), ma1, ma2, cv2.INTER_NEAREST, borderValue=0) > 0
    ga, gb = cv2.cvtColor(ra_img, cv2.COLOR_RGB2GRAY), cv2.cvtColor(rb_img, cv2.COLOR_RGB2GRAY)
    bs = p.block_size_px
    sgbm = cv2.StereoSGBM_create(minDisparity=min_d, numDisparities=num, blockSize=bs, P1=8 * bs * bs, P2=32 * bs * bs,
                                 disp12MaxDiff=1, uniquenessRatio=p.uniqueness_pct, speckleWindowSize=p.speckle_window_px,
                                 speckleRange=2, mode=cv2.STEREO_SGBM_MODE_SGBM)
    d = sgbm.compute(ga, gb).astype(np.float32) / 16.0
    ok = d > min_d - 0.5  # SGBM marks no match with min_d - 1 (the range may be negative: b left of a)
    ok &= valid_a
    # no texture, no match: SGM's smoothness term carries a disparity across sky and uniform
    # areas, which triangulates to a surface that is not there
    gf = ga.astype(np.float32)
    k = (bs, bs)
    local_sd = np.sqrt(np.maximum(cv2.blur(gf * gf, k) - cv2.blur(gf, k) ** 2, 0))
    ok &= local_sd >= p.min_texture_dn
    # check against the bundle: the SfM tie points seen in both photos must get their disparity
    iu, iv = np.rint(ua[inside]).astype(int), np.rint(va[inside]).astype(int)
    iu, iv = np.clip(iu, 0, w - 1), np.clip(iv, 0, h - 1)
    hit = ok[iv, iu]
    agree = np.abs(d[iv, iu][hit] - disp[hit])
    if hit.sum() < 10 or np.median(agree) > p.max_tie_disagreement_px:
        log.info("pair %s-%s left out: %d tie points matched, median disparity disagreement %.1f px",
                 a.name, b.name, int(hit.sum()), float(np.median(agree)) if hit.any() else float("nan"))
        return empty
    pts = cv2.reprojectImageTo3D(d, Q)  # a's rectified camera frame
    ok &= np.isfinite(pts).all(axis=2) & (pts[..., 2] > 0)
    Xr = pts[ok].astype(np.float64)
    X = Xr @ R1  # rectified → a-camera
    xyz = (X - a.t) @ a.R  # a-camera → model
    return xyz, ra_img[ok]


def dense_points(
    photos: list[OrientedPhoto], images: dict[str, np.ndarray], sparse_xyz: np.ndarray, p: PairMatching
) -> tuple[np.ndarray, np.ndarray, int]:
    """Dense points of all ring pairs (model frame), their colours and the number of pairs matched.

    Parameters
    ----------
    photos : list of OrientedPhoto
        Registered photos of the ring.
    images : mapping
        RGB photo (H, W, 3) uint8 of each photo name.
    sparse_xyz : ndarray (N, 3)
        Sparse SfM points (model frame).
    p : PairMatching
        Matching settings.

    Returns
    -------
    xyz : ndarray (N, 3) float64
        Dense points of all pairs (model frame).
    colours : ndarray (N, 3) uint8
        Colour of each point, from the first photo of its pair.
    n_pairs : int
        Number of pairs that gave points.
    """
    pairs = ring_pairs(photos, p)
    xyz, rgb, n_ok = [], [], 0
    for k, (i, j) in enumerate(pairs):
        X, C = match_pair(images[photos[i].name], images[photos[j].name], photos[i], photos[j], sparse_xyz, p)
        if len(X):
            n_ok += 1
            xyz.append(X)
            rgb.append(C)
        if (k + 1) % 10 == 0 or k + 1 == len(pairs):
            log.info("dense matching: %d/%d pairs, %d points so far", k + 1, len(pairs), sum(len(x) for x in xyz))
    if not xyz:
        return np.zeros((0, 3)), np.zeros((0, 3), np.uint8), 0
    return np.concatenate(xyz), np.concatenate(rgb), n_ok
