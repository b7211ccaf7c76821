"""The 3-D control field of Moritani et al. (2010, sect. 2, Table 1), its camera stations and simulated measurements.

The field: 32 targets known to 0.2 mm, 20 on top of square poles of three heights and 12 on the table between
them in three lines. Each camera photographs it six times from H ≈ 3 m, shifted parallel to the field so the
targets cover every corner of the frame, where radial distortion is largest (:func:`calibration_poses`);
:func:`convergent_poses` adds tilted stations. The inner orientation from these is
:mod:`kitegully.stereo.calibration`; the targets rendered and measured in photographs,
:mod:`kitegully.stereo.calibration_targets`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kitegully.stereo.rig import nadir_pose
from kitegully.twin.camera import Camera, Pose


@dataclass(frozen=True)
class ControlField:
    """Calibration targets: ids and world coordinates (m), z up."""

    ids: np.ndarray
    xyz: np.ndarray


def calibration_field(size_m: tuple[float, float] = (0.9, 0.6), pole_heights_m: tuple[float, float, float] = (0.10, 0.20, 0.30)) -> ControlField:
    """The paper's 3-D field: 20 pole tops (5 × 4, three heights in turn) + 12 table points.

    Parameters
    ----------
    size_m : (float, float)
        Extent of the pole grid (x, y), m. [I] The field fills most of the 1.35 × 0.90 m
        footprint of a 51.4 mm lens at 3 m so that shifted images put targets in every corner.
    pole_heights_m : three floats
        Pole heights (m). [I] The paper gives "three different lengths" but no values;
        0.1–0.3 m (up to 10 % of H) gives the depth relief that separates f from distance.

    Returns
    -------
    ControlField
        32 targets, ids ``P01``–``P20`` (poles) and ``T01``–``T12`` (table).
    """
    sx, sy = size_m
    xs, ys = np.linspace(-sx / 2, sx / 2, 5), np.linspace(-sy / 2, sy / 2, 4)
    pts, ids = [], []
    for j, y in enumerate(ys):
        for i, x in enumerate(xs):
            pts.append((x, y, pole_heights_m[(i + j) % 3]))
            ids.append(f"P{len(ids) + 1:02d}")
    xm = (xs[:-1] + xs[1:]) / 2
    for j in range(3):
        y = (ys[j] + ys[j + 1]) / 2
        for x in xm:
            pts.append((x, y, 0.0))
            ids.append(f"T{len(ids) - 19:02d}")
    return ControlField(np.array(ids), np.array(pts, float))


def calibration_poses(H_m: float = 3.0, shift_m: tuple[float, float] = (0.22, 0.13)) -> list[Pose]:
    """Six camera stations at ``H_m`` over the field, shifted on a 3 × 2 grid, slightly tilted and swung.

    [I] The shifts put the field into the left/centre/right and upper/lower parts of the
    frame; swings of a few degrees (κ) and tilts (ω, φ ≤ 3°) are what a hand-held or
    tripod set-up gives and decorrelate the principal point from the pose.
    """
    poses = []
    k = 0
    for sy in (-shift_m[1], shift_m[1]):
        for sx in (-shift_m[0], 0.0, shift_m[0]):
            om, ph, ka = [(2.0, -1.5, 3.0), (-1.0, 2.5, -4.0), (3.0, 1.0, 6.0), (-2.5, -2.0, -2.0), (1.5, 3.0, 4.0), (-3.0, -1.0, -6.0)][k]
            poses.append(nadir_pose(np.array([sx, sy, H_m]), om, ph, ka))
            k += 1
    return poses


def convergent_poses(H_m: float = 3.0, offset_m: float = 1.5, n: int = 8, aim_z_m: float = 0.1,
                     corner_fraction: float = 0.0, frame_px: tuple[int, int, float] = (2464, 1632, 51.4 / 0.0094)) -> list[Pose]:
    """``n`` convergent stations on a circle of radius ``offset_m`` at ``H_m``, all aimed at the field, rolled 0/90/180/270°.

    [I] Beyond the paper's six parallel shifted images: a station 1.5 m off-centre at 3 m
    views the field 27° off-nadir, so f and the camera distance change the image
    differently (the f–distance correlation of near-nadir images is what lets the 0.2 mm
    field error into f), and the rolls decorrelate the principal point from the poses.
    Aimed at the field's centre (``corner_fraction = 0``), targets stay within 0.63 of the
    half-diagonal, so the paper's shifted images are still needed for K1, K2.

    ``corner_fraction`` > 0 turns each camera so that the field's centre is imaged that
    fraction of the way from the frame centre to a frame corner (the four corners in turn,
    ``frame_px`` = width, height, f in px): the same field then reaches into the corners, as
    a real calibration places a small field. Measured (docs/stages/09_stereo.md), 0.5 *instead
    of* the aimed images lowers the standard error of the corner displacement by a quarter but
    costs f precision; *beside* them (stations ``paper+convergent+corners``, the stage's setting
    since session 26) it brings K1 within 10 % on every seed and keeps f.

    Parameters
    ----------
    H_m : float
        Height of the stations (world z, m).
    offset_m : float
        Radius of the circle of stations about the field's centre (m).
    n : int
        Number of stations, evenly spaced round the circle.
    aim_z_m : float
        Height of the aim point above the field's centre (m).
    corner_fraction : float
        Fraction of the way from the frame centre to a frame corner at which the field's centre is imaged; 0 aims at it.
    frame_px : (int, int, float)
        Frame width, height and f (px); used only when ``corner_fraction`` > 0.

    Returns
    -------
    list[Pose]
        One pose per station (world → camera), station k at the angle 2πk/n.
    """
    from kitegully.stereo.rig import look_at_pose

    rolls = (0.0, 90.0, 180.0, 270.0)
    W, Hpx, fpx = frame_px
    out = []
    for k in range(n):
        a = 2 * np.pi * k / n
        C = np.array([offset_m * np.cos(a), offset_m * np.sin(a), H_m])
        pose = look_at_pose(C, np.array([0.0, 0.0, aim_z_m]), 0.0, 0.0, rolls[k % 4])
        if corner_fraction > 0:
            sx, sy = [(1, 1), (-1, 1), (-1, -1), (1, -1)][(k + k // 4) % 4]
            v = np.array([sx * corner_fraction * W / 2 / fpx, sy * corner_fraction * Hpx / 2 / fpx, 1.0])
            v /= np.linalg.norm(v)
            e = np.array([0.0, 0.0, 1.0])
            w, c = np.cross(e, v), float(e @ v)
            V = np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])
            pose = Pose(R=(np.eye(3) + V + V @ V / (1 + c)) @ pose.R, C=C)  # rotation taking the axis e to v
        out.append(pose)
    return out


@dataclass(frozen=True)
class Observation:
    """Target measurements in one image: ids and pixel positions (N × 2)."""

    ids: np.ndarray
    uv: np.ndarray


def simulate_observations(camera: Camera, field: ControlField, poses: list[Pose], sigma_px: float = 0.0,
                          rng: np.random.Generator | None = None, margin_px: float = 5.0) -> list[Observation]:
    """Project the targets into each image (targets outside the frame are not seen), plus Gaussian noise ``sigma_px``.

    Parameters
    ----------
    camera : Camera
        Camera the targets are projected through (distortion included).
    field : ControlField
        Target ids and world coordinates (m).
    poses : list[Pose]
        One pose per image.
    sigma_px : float
        Standard deviation of the noise added to each pixel coordinate (px); 0 adds none.
    rng : Generator or None
        Noise generator; ``None`` uses ``default_rng(0)``.
    margin_px : float
        A target is seen only if it projects at least this far inside the frame's border (px).

    Returns
    -------
    list[Observation]
        One observation per pose, holding only the targets seen.
    """
    obs = []
    for pose in poses:
        uv = camera.project(field.xyz, pose)
        ok = camera.in_image(uv, margin_px) & np.isfinite(uv).all(axis=1)
        uv = uv[ok]
        if sigma_px > 0:
            uv = uv + (rng if rng is not None else np.random.default_rng(0)).normal(0.0, sigma_px, uv.shape)
        obs.append(Observation(field.ids[ok], uv))
    return obs
