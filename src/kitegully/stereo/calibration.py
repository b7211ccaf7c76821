"""Inner orientation on a 3-D control field (Moritani et al. 2010, sect. 2, Table 1).

The field: 32 targets known to 0.2 mm, 20 on top of square poles of three heights and 12
on the table between them in three lines. Each camera photographs it six times from
H ≈ 3 m, shifted parallel to the field so the targets cover every corner of the frame,
where radial distortion is largest.

Solver: OpenCV's ``calibrateCamera`` (Levenberg–Marquardt bundle over the per-image poses
and the shared intrinsics, control coordinates held fixed). Why OpenCV and not
:mod:`kitegully.georef.bundle`: the control field is known (0.2 mm ≪ the 1.7 mm ground
pixel at 3 m), so there are no tie points to adjust and the problem is exactly
calibrateCamera's; its camera model (one f with a fixed aspect ratio, principal point,
k1, k2 on normalised coordinates, no tangential terms) is the twin camera's. A 3-D rig
has no closed-form start in OpenCV, so ``CALIB_USE_INTRINSIC_GUESS`` is set with the
nominal 50 mm lens, the image centre and zero distortion as the start (OpenCV 5 docs:
"3D calibration rigs can also be used as long as initial cameraMatrix is provided").
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from kitegully import InputError
from kitegully.stereo.rig import D2H_NOMINAL_F_MM, PAPER_TABLE1, camera_to_table, nadir_pose
from kitegully.twin.camera import Camera, Pose

if TYPE_CHECKING:
    from kitegully.stereo.measure import PrintedMarks

log = logging.getLogger(__name__)

#: Minimum targets per image for a pose plus intrinsics (6 for a 3-D DLT-like start).
MIN_POINTS_PER_IMAGE = 6


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


@dataclass(frozen=True)
class CalibrationResult:
    """Recovered inner orientation of one camera.

    Attributes
    ----------
    camera : Camera
        Calibrated camera (f, cx, cy, k1, k2).
    rms_px : float
        RMS reprojection error of all targets (px).
    poses : list[Pose]
        Recovered pose of each image.
    n_observations : int
        Target measurements used.
    covariance : ndarray or None
        A-posteriori covariance (5 × 5) of ``(f, cx, cy, k1, k2)`` (px, px, px, normalised,
        normalised) from the bundle's Jacobian, scaled by the variance factor; ``None`` for
        :func:`calibrate_camera` (OpenCV gives no covariance).
    """

    camera: Camera
    rms_px: float
    poses: list
    n_observations: int
    covariance: np.ndarray | None = None


def _check(field: ControlField, observations: list[Observation], name: str) -> None:
    if len(observations) < 2:
        raise InputError(f"{name}: calibration needs at least two images, got {len(observations)}")
    known = set(field.ids.tolist())
    counts: dict[str, int] = {}
    for k, ob in enumerate(observations):
        if len(ob.ids) != len(ob.uv):
            raise InputError(f"{name}: image {k} has {len(ob.ids)} target ids but {len(ob.uv)} pixel positions")
        unknown = sorted(set(ob.ids.tolist()) - known)
        if unknown:
            raise InputError(f"{name}: image {k} measures target {unknown[0]!r}, which is not in the control field")
        if len(ob.ids) < MIN_POINTS_PER_IMAGE:
            raise InputError(f"{name}: image {k} sees {len(ob.ids)} targets; each image needs at least {MIN_POINTS_PER_IMAGE}")
        for i in ob.ids.tolist():
            counts[i] = counts.get(i, 0) + 1
    once = sorted(i for i, c in counts.items() if c == 1)
    if once:
        raise InputError(f"{name}: calibration point {once[0]!r} is seen in only one image; every measured target must appear in at least two images")


def calibrate_camera(field: ControlField, observations: list[Observation], width: int, height: int, pixel_mm: float,
                     nominal_f_mm: float = D2H_NOMINAL_F_MM, name: str = "camera", template: Camera | None = None) -> CalibrationResult:
    """Least-squares bundle for f, x0, y0, K1, K2 with the control field held fixed.

    Parameters
    ----------
    field : ControlField
        Known target coordinates (m).
    observations : list[Observation]
        Target measurements per image; every target must be seen in ≥ 2 images and every
        image must see ≥ 6 targets.
    width, height : int
        Image size (px).
    pixel_mm : float
        Pixel pitch (mm), to start f at ``nominal_f_mm / pixel_mm``.
    nominal_f_mm : float
        Nominal focal length used as the initial guess (mm).
    name : str
        Camera name for error messages.
    template : Camera, optional
        Camera whose non-intrinsic fields (sensor size, make) are copied to the result.

    Returns
    -------
    CalibrationResult

    Notes
    -----
    Cost: a few Levenberg–Marquardt iterations over 6 + 6·images unknowns; milliseconds.
    """
    import cv2

    _check(field, observations, name)
    index = {i: k for k, i in enumerate(field.ids.tolist())}
    obj = [field.xyz[[index[i] for i in ob.ids.tolist()]].astype(np.float32) for ob in observations]
    img = [np.asarray(ob.uv, np.float32).reshape(-1, 1, 2) for ob in observations]
    f0 = nominal_f_mm / pixel_mm
    K0 = np.array([[f0, 0, (width - 1) / 2.0], [0, f0, (height - 1) / 2.0], [0, 0, 1]], float)
    flags = (cv2.CALIB_USE_INTRINSIC_GUESS | cv2.CALIB_FIX_ASPECT_RATIO | cv2.CALIB_ZERO_TANGENT_DIST | cv2.CALIB_FIX_K3)
    crit = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 200, 1e-12)
    rms, K, dist, rvecs, tvecs = cv2.calibrateCamera(obj, img, (width, height), K0, np.zeros(5), flags=flags, criteria=crit)
    dist = np.ravel(dist)
    base = template if template is not None else Camera(width=width, height=height, f=f0, cx=K0[0, 2], cy=K0[1, 2],
                                                      sensor_width_mm=width * pixel_mm, sensor_height_mm=height * pixel_mm,
                                                      focal_length_mm=nominal_f_mm)
    cam = Camera(**{**base.__dict__, "f": float(K[0, 0]), "cx": float(K[0, 2]), "cy": float(K[1, 2]),
                    "k1": float(dist[0]), "k2": float(dist[1])})
    poses = []
    for rv, tv in zip(rvecs, tvecs):
        R = cv2.Rodrigues(rv)[0]
        poses.append(Pose(R=R, C=-R.T @ np.ravel(tv)))
    n = int(sum(len(o.ids) for o in observations))
    log.info("%s: calibrated on %d images, %d observations, RMS %.3f px", name, len(observations), n, rms)
    return CalibrationResult(cam, float(rms), poses, n)


def calibration_table(results: dict[str, CalibrationResult], truth: dict[str, Camera]) -> pd.DataFrame:
    """Table 1 regenerated: recovered vs simulated-truth vs paper inner orientation per camera.

    Returns
    -------
    pandas.DataFrame
        One row per (camera, parameter) with columns ``recovered``, ``truth``, ``paper``,
        ``error`` (recovered − truth) and ``rel_error_pct``; units in the ``unit`` column.
    """
    units = {"f_mm": "mm", "x0_mm": "mm", "y0_mm": "mm", "K1": "mm^-2", "K2": "mm^-4"}
    rows = []
    for side, res in results.items():
        rec, tru = camera_to_table(res.camera), camera_to_table(truth[side])
        paper = PAPER_TABLE1.get(side, {})
        for key, unit in units.items():
            err = rec[key] - tru[key]
            rows.append({"camera": side, "parameter": key.removesuffix("_mm"), "unit": unit, "recovered": rec[key],
                         "truth": tru[key], "paper": paper.get(key, np.nan), "error": err,
                         "rel_error_pct": 100.0 * err / tru[key] if tru[key] != 0 else np.nan})
    return pd.DataFrame(rows)


def _rodrigues_batch(rv: np.ndarray) -> np.ndarray:
    """Rotation matrices (N × 3 × 3) of rotation vectors (N × 3)."""
    th = np.linalg.norm(rv, axis=1)[:, None, None]
    safe = np.where(th > 1e-12, th, 1.0)
    k = rv[:, :, None] / safe[:, :, 0][:, :, None]
    K = np.zeros((len(rv), 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -k[:, 2, 0], k[:, 1, 0], -k[:, 0, 0]
    K[:, 1, 0], K[:, 2, 0], K[:, 2, 1] = k[:, 2, 0], -k[:, 1, 0], k[:, 0, 0]
    eye = np.broadcast_to(np.eye(3), K.shape)
    R = eye + np.sin(safe) * K + (1 - np.cos(safe)) * (K @ K)
    return np.where(th > 1e-12, R, eye + _skew(rv))


def _skew(v: np.ndarray) -> np.ndarray:
    S = np.zeros((len(v), 3, 3))
    S[:, 0, 1], S[:, 0, 2], S[:, 1, 2] = -v[:, 2], v[:, 1], -v[:, 0]
    S[:, 1, 0], S[:, 2, 0], S[:, 2, 1] = v[:, 2], -v[:, 1], v[:, 0]
    return S


def calibrate_camera_weighted(field: ControlField, observations: list[Observation], width: int, height: int, pixel_mm: float,
                              sigma_px: float, sigma_field_m: float, nominal_f_mm: float = D2H_NOMINAL_F_MM,
                              name: str = "camera", template: Camera | None = None) -> tuple[CalibrationResult, np.ndarray]:
    """Self-calibrating bundle with the control field as weighted observations (free network with weighted control).

    Unknowns: f, cx, cy, k1, k2, the pose of every image and the 3-D position of every
    target. Observations: the image measurements (σ = ``sigma_px``) and the field
    coordinates (σ = ``sigma_field_m`` per coordinate). The targets may move within their
    stated accuracy when the images say so, so the 0.2 mm field error is no longer forced
    into f; the control still fixes the datum (position, orientation, scale) through its
    weights, so there is no datum defect. Started from :func:`calibrate_camera` (control
    held fixed).

    [I] Why: with near-nadir stations f and the camera distance are nearly
    interchangeable; only the 0.3 m of pole relief separates them, so a horizontal target
    error of 0.2 mm moves f by ~0.1 mm when the field is held fixed. Letting the targets
    move only helps where the images determine them better than 0.2 mm, i.e. with
    convergent stations (good intersection angles); see :func:`calibration_poses`.

    Parameters
    ----------
    field : ControlField
        Stated target coordinates (m) with their error.
    observations : list[Observation]
        Target measurements per image (checked as in :func:`calibrate_camera`).
    width, height : int
        Image size (px).
    pixel_mm : float
        Pixel pitch (mm).
    sigma_px, sigma_field_m : float
        Standard deviations of the image measurements (px) and of each field coordinate (m), > 0.
    nominal_f_mm, name, template
        As in :func:`calibrate_camera`.

    Returns
    -------
    (CalibrationResult, ndarray)
        The calibration (``rms_px`` of the image residuals) and the adjusted target coordinates (32 × 3, m).

    Notes
    -----
    Cost: sparse Levenberg–Marquardt-like trust-region solve over 5 + 6·images + 3·targets
    unknowns with finite-difference Jacobians; ≈ 400 evaluations, about 4 s of one core for 32 targets and 14 images.
    """
    from scipy.optimize import least_squares
    from scipy.sparse import coo_matrix

    if not (sigma_px > 0 and sigma_field_m > 0):
        raise InputError(f"{name}: sigma_px = {sigma_px} and sigma_field_m = {sigma_field_m} must both be positive")
    start = calibrate_camera(field, observations, width, height, pixel_mm, nominal_f_mm, name, template)
    index = {i: k for k, i in enumerate(field.ids.tolist())}
    n_img, n_pt = len(observations), len(field.ids)
    img_of = np.concatenate([np.full(len(o.ids), k) for k, o in enumerate(observations)])
    pt_of = np.concatenate([[index[i] for i in o.ids.tolist()] for o in observations]).astype(int)
    uv = np.vstack([o.uv for o in observations])
    c = start.camera
    rv0 = np.array([cv2_rvec(p.R) for p in start.poses])
    t0 = np.array([p.t for p in start.poses])
    x0 = np.concatenate([[c.f, c.cx, c.cy, c.k1, c.k2], np.hstack([rv0, t0]).ravel(), field.xyz.ravel()])

    def resid(p):
        f, cx, cy, k1, k2 = p[:5]
        ext = p[5:5 + 6 * n_img].reshape(n_img, 6)
        X = p[5 + 6 * n_img:].reshape(n_pt, 3)
        R = _rodrigues_batch(ext[:, :3])
        Xc = np.einsum("nij,nj->ni", R[img_of], X[pt_of]) + ext[img_of, 3:]
        xn, yn = Xc[:, 0] / Xc[:, 2], Xc[:, 1] / Xc[:, 2]
        r2 = xn * xn + yn * yn
        s = 1 + k1 * r2 + k2 * r2 * r2
        r_img = (np.column_stack([f * xn * s + cx, f * yn * s + cy]) - uv) / sigma_px
        r_fld = (X - field.xyz) / sigma_field_m
        return np.concatenate([r_img.ravel(), r_fld.ravel()])

    m = 2 * len(uv) + 3 * n_pt
    r_i, c_i = [], []
    for a in (0, 1):
        r = 2 * np.arange(len(uv)) + a
        cols = np.column_stack([np.tile(np.arange(5), (len(uv), 1)), 5 + 6 * img_of[:, None] + np.arange(6),
                                5 + 6 * n_img + 3 * pt_of[:, None] + np.arange(3)])
        r_i.append(np.repeat(r, cols.shape[1]))
        c_i.append(cols.ravel())
    r_i.append(2 * len(uv) + np.arange(3 * n_pt))
    c_i.append(5 + 6 * n_img + np.arange(3 * n_pt))
    S = coo_matrix((np.ones(sum(len(v) for v in r_i), np.int8), (np.concatenate(r_i), np.concatenate(c_i))), shape=(m, len(x0)))
    sol = least_squares(resid, x0, jac_sparsity=S, x_scale="jac", method="trf", xtol=1e-10, ftol=1e-10, gtol=1e-10, max_nfev=1000)
    log.debug("%s: weighted bundle %d evaluations, status %d", name, sol.nfev, sol.status)
    p = sol.x
    cam = Camera(**{**c.__dict__, "f": float(p[0]), "cx": float(p[1]), "cy": float(p[2]), "k1": float(p[3]), "k2": float(p[4])})
    ext = p[5:5 + 6 * n_img].reshape(n_img, 6)
    R = _rodrigues_batch(ext[:, :3])
    poses = [Pose(R=R[k], C=-R[k].T @ ext[k, 3:]) for k in range(n_img)]
    r = resid(p)[:2 * len(uv)] * sigma_px
    rms = float(np.sqrt(np.mean(r.reshape(-1, 2) ** 2) * 2))
    # a-posteriori covariance of the intrinsics: (JᵀJ)⁻¹ (residuals already in units of their σ) × variance factor
    J = sol.jac.toarray() if hasattr(sol.jac, "toarray") else np.asarray(sol.jac)
    s0 = float(2 * sol.cost / max(1, m - len(x0)))
    cov = np.linalg.pinv(J.T @ J)[:5, :5] * s0
    log.info("%s: weighted-control bundle on %d images: RMS %.3f px, targets moved %.3f mm RMS", name, n_img, rms,
             1e3 * float(np.sqrt(np.mean((p[5 + 6 * n_img:].reshape(n_pt, 3) - field.xyz) ** 2))))
    return CalibrationResult(cam, rms, poses, len(uv), cov), p[5 + 6 * n_img:].reshape(n_pt, 3)


def cv2_rvec(R: np.ndarray) -> np.ndarray:
    """Rotation vector of a rotation matrix (OpenCV's Rodrigues)."""
    import cv2

    return cv2.Rodrigues(np.asarray(R, float))[0].ravel()


def distortion_precision(result: CalibrationResult, truth: Camera | None = None) -> dict[str, float]:
    """Precision of the recovered radial distortion: K1 with its standard error, its correlations, the edge displacement.

    Parameters
    ----------
    result : CalibrationResult
        A calibration with a ``covariance`` (from :func:`calibrate_camera_weighted`).
    truth : Camera, optional
        The simulated true camera, for the errors (recovered − truth).

    Returns
    -------
    dict
        ``K1``, ``K1_se`` (mm⁻²), ``corr_K1_K2``, ``corr_K1_f``, the radial displacement
        ``Δr = K1 r³ + K2 r⁵`` at the frame corner ``edge_dr_px`` and its standard error
        ``edge_dr_se_px`` (px, from the K1–K2 covariance), and with ``truth``: ``K1_err_pct``,
        ``K1_err_in_se`` and ``edge_dr_err_px`` (recovered − true displacement at the corner).

    Notes
    -----
    The displacement at the corner is what a DEM sees of the distortion: K1 and K2 both
    describe it and trade against each other, so K1 alone can be off by tens of percent while
    Δr at the corner is right to a few hundredths of a pixel.
    """
    if result.covariance is None:
        raise InputError("distortion_precision: the calibration has no covariance (use calibrate_camera_weighted)")
    cam = result.camera
    pitch = cam.pixel_pitch_mm
    f_mm = cam.f * pitch
    # K1 = k1/f_mm², K2 = k2/f_mm⁴: linearised transformation of (f, k1, k2)
    k1, k2 = cam.k1, cam.k2
    G = np.zeros((3, 5))  # rows: f_mm, K1, K2; columns: f, cx, cy, k1, k2
    G[0, 0] = pitch
    G[1, 0], G[1, 3] = -2 * k1 / f_mm**3 * pitch, 1 / f_mm**2
    G[2, 0], G[2, 4] = -4 * k2 / f_mm**5 * pitch, 1 / f_mm**4
    C = G @ result.covariance @ G.T
    sd = np.sqrt(np.diag(C))
    K1, K2 = k1 / f_mm**2, k2 / f_mm**4
    r_mm = float(np.hypot(cam.width / 2, cam.height / 2) * pitch)
    g = np.array([0.0, r_mm**3, r_mm**5])
    out = {"K1": K1, "K1_se": float(sd[1]), "K2": K2, "K2_se": float(sd[2]), "f_mm_se": float(sd[0]),
           "corr_K1_K2": float(C[1, 2] / (sd[1] * sd[2])), "corr_K1_f": float(C[0, 1] / (sd[0] * sd[1])),
           "edge_r_mm": r_mm, "edge_dr_px": float((K1 * r_mm**3 + K2 * r_mm**5) / pitch),
           "edge_dr_se_px": float(np.sqrt(g @ C @ g) / pitch)}
    if truth is not None:
        t1, t2 = truth.k1 / (truth.f * pitch) ** 2, truth.k2 / (truth.f * pitch) ** 4
        out["K1_err_pct"] = float(100 * (K1 - t1) / t1)
        out["K1_err_in_se"] = float((K1 - t1) / sd[1])
        out["edge_dr_err_px"] = float(out["edge_dr_px"] - (t1 * r_mm**3 + t2 * r_mm**5) / pitch)
    return out


# ----------------------------------------------------------------------------- targets measured in rendered photographs
#: Target disc diameter (m). [I] 10 mm, the frame marks' print (:class:`kitegully.stereo.measure.MarkDesign`):
#: the ground pixel is 3.0 m · 0.0094 / 51.4 = 0.55 mm under the nadir stations and at most
#: 3.6 m · 0.0094 / 51.4 = 0.66 mm at the far side of the field from a convergent station, so a disc is
#: 15–18 px across: every pixel of it enters the centroid (close-range practice asks ≥ 5–10 px), and its
#: 24 mm black plate (≤ 44 px) stays far inside the 0.10–0.15 m spacing of the targets.
TARGET_DIAMETER_M = 0.010


def calibration_targets(field: ControlField, diameter_m: float = TARGET_DIAMETER_M) -> PrintedMarks:
    """The field's targets as printed discs: a white disc on a black square plate, horizontal, centred on each target.

    Pole tops carry the plate on the pole (the pole itself is not rendered: under the plate it is hidden
    from the nadir stations, and from the 27° convergent stations its side appears beyond the plate's
    edge, outside the centroid's background annulus of radius 2r < the plate's half side 2.4r·cos 27°).
    """
    from kitegully.stereo.measure import MarkDesign, PrintedMarks

    return PrintedMarks(np.asarray(field.xyz, float), MarkDesign(diameter_m))


def render_calibration_image(camera: Camera, pose: Pose, targets: PrintedMarks, noise_dn: float,
                             rng: np.random.Generator, window: tuple[int, int, int, int] | None = None) -> np.ndarray:
    """One calibration photograph: the printed targets over a plain grey table (reflectance 0.30), 0–255 float.

    [I] The table's texture is irrelevant to a target: each disc is measured against its own black plate.
    The table top is 1 mm below the table targets' print (a card on the table), so the ray hits the plate first.
    Cost: O(pixels · targets) for the exact ray–plate intersections (:meth:`PrintedMarks.intersect`).

    Parameters
    ----------
    camera, pose : Camera, Pose
        Inner and exterior orientation of the station.
    targets : PrintedMarks
        The printed targets (:func:`calibration_targets`).
    noise_dn : float
        Standard deviation of the Gaussian image noise (digital numbers).
    rng : Generator
        Noise generator.
    window : (x0, y0, x1, y1) or None
        Render only this pixel window (end exclusive); the rest of the frame is NaN. ``None`` renders the whole frame.

    Returns
    -------
    ndarray (height, width) float32
        The photograph, 0–255 plus noise; NaN outside ``window``.
    """
    from kitegully.stereo.synth import Texture, render_heightfield

    table = Texture(np.full((400, 400), 0.30, np.float32), -2.0, 2.0, 0.01)
    return render_heightfield(camera, pose, lambda x, y: np.full_like(x, -1e-3), table, z_start=-1e-3, noise_dn=noise_dn, rng=rng,
                              window=window, marks=targets)


def projected_disc_offset_px(camera: Camera, pose: Pose, xyz: np.ndarray, radius_m: float, n: int = 720) -> np.ndarray:
    """Offset (N × 2, px) of the area centroid of each imaged disc from the image of its centre.

    A circle's perspective image is an ellipse whose centre is not the image of the circle's
    centre: to first order the shift is f·r²·sin θ·cos θ / Z² (θ the plate's tilt to the image
    plane, Z its distance), plus the (smaller) share of the lens distortion's curvature across the
    disc. Computed exactly here: the disc's rim (``n`` points, horizontal plate) is projected
    through ``camera`` (distortion included) and the centroid of the polygon it bounds taken
    (shoelace formula). O(N · n).

    Parameters
    ----------
    camera, pose : Camera, Pose
        Inner and exterior orientation.
    xyz : ndarray (N, 3)
        Disc centres, world coordinates (m).
    radius_m : float
        Disc radius (m).
    n : int
        Number of rim points per disc.

    Returns
    -------
    ndarray (N, 2)
        Centroid of each imaged disc minus the image of its centre (px).
    """
    a = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    X = np.asarray(xyz, float)
    rim = X[:, None, :] + radius_m * np.stack([np.cos(a), np.sin(a), np.zeros_like(a)], axis=1)[None]
    uv = camera.project(rim.reshape(-1, 3), pose).reshape(len(X), n, 2)
    x, y = uv[..., 0], uv[..., 1]
    x1, y1 = np.roll(x, -1, axis=1), np.roll(y, -1, axis=1)
    cr = x * y1 - x1 * y
    A = 0.5 * cr.sum(axis=1)
    cx = ((x + x1) * cr).sum(axis=1) / (6 * A)
    cy = ((y + y1) * cr).sum(axis=1) / (6 * A)
    return np.column_stack([cx, cy]) - camera.project(X, pose)


@dataclass(frozen=True)
class TargetMeasurement:
    """Targets located in one calibration photograph: the observation, each centroid's σ from the image noise (px), and the ids dropped at the frame edge."""

    observation: Observation
    sigma_px: np.ndarray
    dropped: tuple[str, ...]


def measure_targets(image: np.ndarray, predict_camera: Camera, pose: Pose, field: ControlField, diameter_m: float,
                    allowance_px: float, name: str) -> TargetMeasurement:
    """Locate every calibration target in one photograph (template + iterated weighted centroid of :mod:`kitegully.stereo.measure`).

    Parameters
    ----------
    image : ndarray (H, W)
        Photograph, 0–255 (NaN = not rendered).
    predict_camera : Camera
        Camera used to predict where each target is (the nominal lens: its f, principal point and
        distortion are what the calibration is to find, so the prediction is off by up to ``allowance_px``).
    pose : Pose
        The station as set up (planned position, tilts and swing).
    field : ControlField
        Target ids and stated coordinates.
    diameter_m : float
        Printed disc diameter (m).
    allowance_px : float
        Bound on the prediction error (px). A target predicted within ``allowance_px`` plus its
        measuring window of the frame's edge that is not found (window leaving the frame, or disc cut
        off) is dropped with a log line (legitimately at the edge of the frame); a target predicted outside the frame by more
        than its window is not looked for.
    name : str
        Image name for messages.

    Returns
    -------
    TargetMeasurement

    Raises
    ------
    InputError
        A target predicted well inside the frame that is not found (window outside the rendered
        part, or disc contrast below 5 σ of the plate's noise): one sentence naming the image and target.

    Notes
    -----
    Search gate: half the smallest predicted spacing of two targets in this image (never reaches a
    neighbour's disc), at most ``2·allowance_px``. Cost: O(targets · gate²), a few ms per target.
    """
    from kitegully.stereo.measure import MARK_DETECTION_SIGMA, predict_marks, search_disc

    P, R = predict_marks(predict_camera, pose, field.xyz, diameter_m)
    img = np.asarray(image, np.float32)
    h, w = img.shape
    edge = np.minimum.reduce([P[:, 0], P[:, 1], w - 1 - P[:, 0], h - 1 - P[:, 1]])  # distance inside the frame (px, < 0 outside)
    need = 2.0 * R + 2.0  # the centroid's background annulus reaches 2r (+ rounding)
    look = edge > -need
    # [I] a target another plate reaches into (its measuring window of radius 2r + 2 overlaps the other plate,
    # half-diagonal 1.2·√2·D): the convergent stations see a 0.3 m pole top over a table target. Predicted from
    # the stated field and the planned station; such a target is not measured in that image (logged).
    dd = np.linalg.norm(P[:, None] - P[None], axis=2)
    dd[np.diag_indices(len(dd))] = np.inf
    crowded = look & ((dd - need[:, None] - 1.2 * np.sqrt(2) * 2 * R[None, :]) < 0).any(axis=1)
    if crowded.any():
        log.info("%s: target(s) %s not measured: another target's plate reaches into the measuring window", name,
                 ", ".join(field.ids[crowded].tolist()))
    look &= ~crowded
    dd = dd[np.ix_(look, look)]
    gate = min(0.5 * float(dd.min()) if len(dd) > 1 else np.inf, 2.0 * allowance_px)
    ids, uv, sig, dropped = [], [], [], []
    for i in np.flatnonzero(~look):
        dropped.append(str(field.ids[i]))
    for i in np.flatnonzero(look):
        p, r = P[i], float(R[i])
        found = search_disc(img, p, r, gate)
        weak = found is None or not found[2] > MARK_DETECTION_SIGMA * max(found[3], 1e-6)
        if weak and edge[i] < allowance_px + need[i]:  # at the frame's edge: cut off or outside, legitimately
            dropped.append(str(field.ids[i]))
            continue
        if found is None or not found[2] > MARK_DETECTION_SIGMA * max(found[3], 1e-6):
            why = ("its measuring window leaves the rendered image" if found is None else
                   f"the brightest disc there has a contrast of {found[2]:.1f} DN against {found[3]:.1f} DN of noise, below {MARK_DETECTION_SIGMA:g} σ")
            raise InputError(f"{name}: calibration target {field.ids[i]} not found within {gate:.0f} px of its predicted position "
                             f"({p[0]:.0f}, {p[1]:.0f}): {why}")
        ids.append(field.ids[i])
        uv.append(found[0])
        sig.append(found[1])
    if dropped:
        log.info("%s: %d target(s) at or beyond the frame's edge not measured: %s", name, len(dropped), ", ".join(dropped))
    return TargetMeasurement(Observation(np.array(ids), np.array(uv, float).reshape(-1, 2)), np.array(sig), tuple(dropped))


def measure_calibration_images(camera: Camera, predict_camera: Camera, field_true: ControlField, stated: ControlField,
                               poses: list[Pose], diameter_m: float, noise_dn: float, rng: np.random.Generator,
                               allowance_px: float, name: str) -> tuple[list[Observation], float]:
    """Twin step + measurement: render each calibration photograph (targets at their true places) and locate the targets.

    Only the part of each frame around a target is rendered (a 241 px window per target, the plates within
    200 px of it): identical pixels there, a fraction of a full frame's cost. Returns the observations and the
    median centroid σ from the image noise (px). Cost: ≈ 0.4 s CPU per image.

    Parameters
    ----------
    camera : Camera
        The true camera the photographs are rendered with.
    predict_camera : Camera
        Camera used to predict where each target is (the nominal lens); it also places the render windows.
    field_true : ControlField
        Targets at their true places (m), as rendered.
    stated : ControlField
        Targets at their stated coordinates (m), as measured against.
    poses : list[Pose]
        One station per photograph.
    diameter_m : float
        Printed disc diameter (m).
    noise_dn : float
        Standard deviation of the Gaussian image noise (digital numbers).
    rng : Generator
        Noise generator.
    allowance_px : float
        Bound on the prediction error (px), as in :func:`measure_targets`.
    name : str
        Camera name for messages; each image is named ``"{name} image {k}"``, k counted from 1.

    Returns
    -------
    observations : list[Observation]
        Targets located in each photograph, one per pose.
    sigma_px : float
        Median centroid σ from the image noise over all targets (px).
    """
    obs, sig = [], []
    for k, pose in enumerate(poses):
        P = predict_camera.project(field_true.xyz, pose)
        img = np.full((camera.height, camera.width), np.nan, np.float32)
        for p in P:
            if not (-60 < p[0] < camera.width + 60 and -60 < p[1] < camera.height + 60):
                continue
            near = np.linalg.norm(P - p, axis=1) < 200
            win = (int(p[0]) - 120, int(p[1]) - 120, int(p[0]) + 121, int(p[1]) + 121)
            sub = render_calibration_image(camera, pose, calibration_targets(ControlField(field_true.ids[near], field_true.xyz[near]), diameter_m),
                                           noise_dn, rng, win)
            x0, y0, x1, y1 = max(0, win[0]), max(0, win[1]), min(camera.width, win[2]), min(camera.height, win[3])
            img[y0:y1, x0:x1] = sub[y0:y1, x0:x1]
        m = measure_targets(img, predict_camera, pose, stated, diameter_m, allowance_px, f"{name} image {k + 1}")
        obs.append(m.observation)
        sig.append(m.sigma_px)
    return obs, float(np.median(np.concatenate(sig)))
