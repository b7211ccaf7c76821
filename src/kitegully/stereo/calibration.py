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

import numpy as np
import pandas as pd

from kitegully import InputError
from kitegully.stereo.control_field import ControlField, Observation
from kitegully.stereo.rig import D2H_NOMINAL_F_MM, PAPER_TABLE1, camera_to_table
from kitegully.twin.camera import Camera, Pose

log = logging.getLogger(__name__)

#: Minimum targets per image for a pose plus intrinsics (6 for a 3-D DLT-like start).
MIN_POINTS_PER_IMAGE = 6


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
