"""Relative orientation and epipolar rectification (Moritani et al. 2010, Fig. 3).

After rectification both images share one coordinate system and corresponding points lie
on the same row, so matching is a 1-D search along x (the epipolar line). OpenCV's
``stereoRectify`` (Bouguet's algorithm) computes the rectifying rotations and the new
projection matrices; ``initUndistortRectifyMap``/``remap`` resample the images and remove
the lens distortion in the same step.

Relative orientation comes either from known poses (:func:`relative_orientation_from_poses`)
or from matched points through the coplanarity condition (:func:`relative_orientation`,
essential matrix on distortion-free normalised coordinates, scaled by the known base).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kitegully import InputError
from kitegully.twin.camera import Camera, Pose

# [I] Re-selections of the inliers against the adjusted relative orientation: the set settles in one
# or two rounds when RANSAC's model was close; five bound the work when it was not.
MAX_INLIER_ROUNDS = 5


def relative_orientation_from_poses(pose_left: Pose, pose_right: Pose) -> tuple[np.ndarray, np.ndarray]:
    """``(R, T)`` with ``x_right = R x_left + T`` (camera frames, m) from two world poses."""
    R = pose_right.R @ pose_left.R.T
    T = pose_right.R @ (pose_left.C - pose_right.C)
    return R, T


def _normalised(camera: Camera, uv: np.ndarray) -> np.ndarray:
    import cv2

    pts = np.asarray(uv, np.float64).reshape(-1, 1, 2)
    return cv2.undistortPoints(pts, camera.K, camera.dist_coeffs).reshape(-1, 2)


def relative_orientation(cam_left: Camera, cam_right: Camera, uv_left: np.ndarray, uv_right: np.ndarray,
                         base_m: float, threshold_px: float = 1.0,
                         approx: tuple[np.ndarray, np.ndarray] | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Relative orientation from matched points (coplanarity condition), scaled to ``base_m``.

    Parameters
    ----------
    cam_left, cam_right : Camera
        Calibrated cameras.
    uv_left, uv_right : ndarray (N, 2)
        Matched pixel positions (N ≥ 8), distorted image coordinates.
    base_m : float
        Known base length (m); the coplanarity condition fixes the base direction only.
    threshold_px : float
        RANSAC inlier threshold (px).
    approx : (R, T), optional
        Approximate relative orientation (e.g. the rig's nominal set-up). Given, the least-squares
        adjustment of the coplanarity condition starts from it instead of the decomposition of the
        RANSAC essential matrix: over a nearly flat scene (a soil box) the essential matrix has two
        nearly equally good decompositions, and the base's sign is not observable in the residuals,
        so photogrammetric software adjusts from approximate values.

    Returns
    -------
    R, T, inliers
        ``x_right = R x_left + T`` and the inlier mask.
    """
    import cv2

    uv_left, uv_right = np.asarray(uv_left, float), np.asarray(uv_right, float)
    if uv_left.shape != uv_right.shape or uv_left.ndim != 2 or uv_left.shape[1] != 2:
        raise InputError(f"relative orientation: matched point arrays differ in shape ({uv_left.shape} vs {uv_right.shape})")
    if len(uv_left) < 8:
        raise InputError(f"relative orientation: {len(uv_left)} matched points given; the coplanarity condition needs at least 8")
    xl, xr = _normalised(cam_left, uv_left), _normalised(cam_right, uv_right)
    f = 0.5 * (cam_left.f + cam_right.f)
    cv2.setRNGSeed(0)  # RANSAC draws from OpenCV's global stream: the same points give the same orientation
    E, mask = cv2.findEssentialMat(xl, xr, np.eye(3), method=cv2.RANSAC, prob=0.9999, threshold=threshold_px / f)
    if E is None or E.shape != (3, 3):
        raise InputError("relative orientation: the matched points admit no unique essential matrix (degenerate geometry)")
    if approx is None:
        _, R, t, mask = cv2.recoverPose(E, xl, xr, np.eye(3), mask=mask)
    else:
        R, t = np.asarray(approx[0], float), np.asarray(approx[1], float).ravel()
    inl = np.ravel(mask).astype(bool)
    R, t = _refine_coplanarity(R, np.ravel(t), xl[inl], xr[inl])
    # The RANSAC's inliers belong to its minimal-sample model: over a flat, narrow scene that model can
    # be far from the adjusted one, so points it accepted may be outliers of the adjustment (and the
    # reverse). The inliers are re-selected against the adjusted model and the adjustment repeated
    # until the set no longer changes, so the result follows from the points, not from RANSAC's draw.
    thr = threshold_px / f
    for _ in range(MAX_INLIER_ROUNDS):
        new = np.abs(_sampson(R, t, xl, xr)) < thr
        if new.sum() < 8 or np.array_equal(new, inl):
            break
        inl = new
        R, t = _refine_coplanarity(R, t, xl[inl], xr[inl])
    return R, t / np.linalg.norm(t) * base_m, inl


def _sampson(R: np.ndarray, t: np.ndarray, xl: np.ndarray, xr: np.ndarray) -> np.ndarray:
    """Sampson distance (normalised image units) of each point pair to the coplanarity condition of (R, t)."""
    t = np.ravel(t) / np.linalg.norm(t)
    tx = np.array([[0, -t[2], t[1]], [t[2], 0, -t[0]], [-t[1], t[0], 0]])
    E = tx @ R
    hl = np.column_stack([xl, np.ones(len(xl))])
    hr = np.column_stack([xr, np.ones(len(xr))])
    Ex, Etx = hl @ E.T, hr @ E
    return np.sum(hr * Ex, axis=1) / np.sqrt(Ex[:, 0] ** 2 + Ex[:, 1] ** 2 + Etx[:, 0] ** 2 + Etx[:, 1] ** 2)


def _refine_coplanarity(R: np.ndarray, t: np.ndarray, xl: np.ndarray, xr: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares refinement of (R, t) minimising the Sampson distance of the coplanarity condition.

    The RANSAC essential matrix is a minimal-sample model; this adjusts all five degrees of
    freedom (rotation vector, base direction) over every inlier.
    """
    import cv2
    from scipy.optimize import least_squares

    t = t / np.linalg.norm(t)
    # base direction on a tangent plane of the unit sphere at t
    a = np.cross(t, [0.0, 0.0, 1.0] if abs(t[2]) < 0.9 else [1.0, 0.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(t, a)

    def unpack(p):
        Rp = cv2.Rodrigues(p[:3])[0] @ R
        tp = t + p[3] * a + p[4] * b
        return Rp, tp / np.linalg.norm(tp)

    def resid(p):
        return _sampson(*unpack(p), xl, xr)

    sol = least_squares(resid, np.zeros(5), method="lm", xtol=1e-14, ftol=1e-14)
    return unpack(sol.x)


@dataclass
class Rectification:
    """Rectifying transforms of one stereo pair (OpenCV conventions).

    Attributes
    ----------
    R1, R2 : ndarray (3, 3)
        Rotations from each camera frame to its rectified frame.
    P1, P2 : ndarray (3, 4)
        Projection matrices of the rectified cameras (the left rectified frame is the reference).
    Q : ndarray (4, 4)
        Disparity-to-depth matrix: ``(x, y, d, 1) → (X, Y, Z, W)`` in the left rectified frame, d = x_l − x_r.
    size : (int, int)
        Rectified image size (width, height).
    """

    cam_left: Camera
    cam_right: Camera
    R1: np.ndarray
    R2: np.ndarray
    P1: np.ndarray
    P2: np.ndarray
    Q: np.ndarray
    size: tuple[int, int]

    @property
    def focal_px(self) -> float:
        """Focal length of the rectified cameras (px): ``P1[0, 0]``."""
        return float(self.P1[0, 0])

    @property
    def base_m(self) -> float:
        """Base of the rectified pair (m): ``−P2[0, 3] / f``."""
        return float(-self.P2[0, 3] / self.P2[0, 0])

    def disparity_for_depth(self, depth_m: float | np.ndarray) -> float | np.ndarray:
        """Disparity (px) of a point at ``depth_m`` along the rectified optical axis."""
        return self.focal_px * self.base_m / np.asarray(depth_m, float) + (self.P1[0, 2] - self.P2[0, 2])

    def rectify_points(self, uv: np.ndarray, side: str) -> np.ndarray:
        """Map distorted pixel positions (N × 2) of the ``side`` image to rectified pixels."""
        import cv2

        cam, R, P = (self.cam_left, self.R1, self.P1) if side == "left" else (self.cam_right, self.R2, self.P2)
        pts = np.asarray(uv, np.float64).reshape(-1, 1, 2)
        return cv2.undistortPoints(pts, cam.K, cam.dist_coeffs, R=R, P=P).reshape(-1, 2)

    def maps(self, side: str) -> tuple[np.ndarray, np.ndarray]:
        """``remap`` tables (float32 x and y) of the ``side`` image."""
        import cv2

        cam, R, P = (self.cam_left, self.R1, self.P1) if side == "left" else (self.cam_right, self.R2, self.P2)
        return cv2.initUndistortRectifyMap(cam.K, cam.dist_coeffs, R, P, self.size, cv2.CV_32FC1)

    def remap(self, image: np.ndarray, side: str, border_value: float = np.nan) -> np.ndarray:
        """Resample one image into the rectified geometry (bilinear); pixels outside get ``border_value``.

        Cost: O(pixels).

        Parameters
        ----------
        image : ndarray (H, W)
            Photograph of one camera (distorted).
        side : str
            ``"left"``; any other value means the right camera.
        border_value : float
            Value of rectified pixels that map outside ``image``.

        Returns
        -------
        ndarray (height, width) float32
            The rectified image, of size :attr:`size`.
        """
        import cv2

        mx, my = self.maps(side)
        img = np.asarray(image, np.float32)
        return cv2.remap(img, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=float(border_value))

    def footprint(self, side: str) -> tuple[float, float, float, float]:
        """Rectified bounding box (xmin, ymin, xmax, ymax) of the ``side`` image's border (px)."""
        cam = self.cam_left if side == "left" else self.cam_right
        n = 50
        u = np.linspace(-0.5, cam.width - 0.5, n)
        v = np.linspace(-0.5, cam.height - 0.5, n)
        border = np.vstack([np.column_stack([u, np.full(n, v[0])]), np.column_stack([u, np.full(n, v[-1])]),
                            np.column_stack([np.full(n, u[0]), v]), np.column_stack([np.full(n, u[-1]), v])])
        r = self.rectify_points(border, side)
        return float(r[:, 0].min()), float(r[:, 1].min()), float(r[:, 0].max()), float(r[:, 1].max())


def rectify_pair(cam_left: Camera, cam_right: Camera, R: np.ndarray, T: np.ndarray,
                 depth_range_m: tuple[float, float], alpha: float = -1.0) -> Rectification:
    """Epipolar rectification of a calibrated pair, with a check that the pair overlaps.

    Parameters
    ----------
    cam_left, cam_right : Camera
        Calibrated cameras (same image size).
    R, T : ndarray
        Relative orientation, ``x_right = R x_left + T`` (m).
    depth_range_m : (float, float)
        Nearest and farthest object distance along the viewing direction (m); the pair must
        overlap for some depth in this range.
    alpha : float
        ``stereoRectify`` free scaling (−1: OpenCV default, 0: only valid pixels, 1: all pixels).

    Returns
    -------
    Rectification
    """
    import cv2

    if (cam_left.width, cam_left.height) != (cam_right.width, cam_right.height):
        raise InputError(f"rectification: image sizes differ ({cam_left.width}×{cam_left.height} vs {cam_right.width}×{cam_right.height})")
    zmin, zmax = depth_range_m
    if not (0 < zmin < zmax):
        raise InputError(f"rectification: depth_range_m {depth_range_m} must be two increasing positive distances")
    T = np.asarray(T, float).ravel()
    if np.linalg.norm(T) <= 0:
        raise InputError("rectification: the base length is zero, so the pair has no stereo geometry")
    size = (cam_left.width, cam_left.height)
    R1, R2, P1, P2, Q, _, _ = cv2.stereoRectify(cam_left.K, cam_left.dist_coeffs, cam_right.K, cam_right.dist_coeffs,
                                                size, np.asarray(R, float), T.reshape(3, 1), flags=0, alpha=alpha)
    if abs(P2[1, 3]) > abs(P2[0, 3]):
        raise InputError("rectification: the base is mostly vertical in the images; this library expects a left/right pair")
    rect = Rectification(cam_left, cam_right, R1, R2, P1, P2, Q, size)
    if rect.base_m < 0:
        raise InputError("rectification: the 'right' camera is left of the 'left' camera; swap the images")
    lx0, ly0, lx1, ly1 = rect.footprint("left")
    rx0, ry0, rx1, ry1 = rect.footprint("right")
    dmin, dmax = sorted(np.ravel(rect.disparity_for_depth(np.array([zmax, zmin]))))
    rows = min(ly1, ry1) - max(ly0, ry0)
    # a right pixel x_r sees a left pixel x_l = x_r + d: the shifted right box must meet the left box
    cols = min(lx1, rx1 + dmax) - max(lx0, rx0 + dmin)
    if rows <= 0 or cols <= 0:
        raise InputError(f"rectification: the left and right images do not overlap at object distances {zmin:g}–{zmax:g} m "
                         f"(B = {rect.base_m:.3g} m); the pair cannot be matched")
    return rect


def vertical_disparity(rect: Rectification, uv_left: np.ndarray, uv_right: np.ndarray) -> np.ndarray:
    """Residual vertical disparity ``y_left − y_right`` (px) of matched points after rectification.

    Zero for a perfect relative orientation and calibration; the check of the rectification.

    Parameters
    ----------
    rect : Rectification
        The pair's rectification.
    uv_left, uv_right : ndarray (N, 2)
        Matched pixel positions in the left and right photographs (distorted, px).

    Returns
    -------
    ndarray (N,)
        ``y_left − y_right`` of each pair in the rectified images (px).
    """
    return rect.rectify_points(uv_left, "left")[:, 1] - rect.rectify_points(uv_right, "right")[:, 1]
