"""Camera geometry in NumPy: rotations, the COLMAP radial camera, multi-view triangulation.

Camera convention (COLMAP): ``x_cam = R @ X + t``; normalised ``u = x/z, v = y/z``;
radial distortion ``d = k1 r² + k2 r⁴`` with ``r² = u² + v²``; pixel
``(f u (1 + d) + cx, f v (1 + d) + cy)``. Intrinsics are ``(f, cx, cy, k1, k2)``
(SIMPLE_RADIAL has ``k2 = 0``).
"""

from __future__ import annotations

import numpy as np


def rotvec_to_matrix(rv: np.ndarray) -> np.ndarray:
    """Rodrigues: (n, 3) rotation vectors to (n, 3, 3) matrices. O(n)."""
    rv = np.atleast_2d(rv)
    theta = np.linalg.norm(rv, axis=1)
    small = theta < 1e-12
    k = rv / np.where(small, 1.0, theta)[:, None]
    K = np.zeros((len(rv), 3, 3))
    K[:, 0, 1], K[:, 0, 2] = -k[:, 2], k[:, 1]
    K[:, 1, 0], K[:, 1, 2] = k[:, 2], -k[:, 0]
    K[:, 2, 0], K[:, 2, 1] = -k[:, 1], k[:, 0]
    s, c = np.sin(theta)[:, None, None], np.cos(theta)[:, None, None]
    R = np.eye(3)[None] + s * K + (1 - c) * (K @ K)
    R[small] = np.eye(3)
    return R


def matrix_to_rotvec(R: np.ndarray) -> np.ndarray:
    """(n, 3, 3) rotation matrices to (n, 3) rotation vectors (via quaternions). O(n)."""
    R = np.asarray(R).reshape(-1, 3, 3)
    q = np.empty((len(R), 4))
    for i, m in enumerate(R):  # n = number of images: small
        w = np.sqrt(max(0.0, 1 + m[0, 0] + m[1, 1] + m[2, 2])) / 2
        x = np.copysign(np.sqrt(max(0.0, 1 + m[0, 0] - m[1, 1] - m[2, 2])) / 2, m[2, 1] - m[1, 2])
        y = np.copysign(np.sqrt(max(0.0, 1 - m[0, 0] + m[1, 1] - m[2, 2])) / 2, m[0, 2] - m[2, 0])
        z = np.copysign(np.sqrt(max(0.0, 1 - m[0, 0] - m[1, 1] + m[2, 2])) / 2, m[1, 0] - m[0, 1])
        q[i] = (w, x, y, z)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    angle = 2 * np.arctan2(np.linalg.norm(q[:, 1:], axis=1), q[:, 0])
    sin_half = np.linalg.norm(q[:, 1:], axis=1)
    axis = q[:, 1:] / np.where(sin_half < 1e-15, 1.0, sin_half)[:, None]
    return axis * angle[:, None]


def rotate(rv: np.ndarray, X: np.ndarray) -> np.ndarray:
    """Rotate points ``X`` (n, 3) by per-row rotation vectors ``rv`` (n, 3) (Rodrigues). O(n)."""
    theta = np.linalg.norm(rv, axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        k = np.where(theta > 1e-12, rv / theta, 0.0)
    cos, sin = np.cos(theta), np.sin(theta)
    kx = np.cross(k, X)
    kd = np.sum(k * X, axis=1, keepdims=True)
    return X * cos + kx * sin + k * kd * (1 - cos)


def project(intr: np.ndarray, rv: np.ndarray, t: np.ndarray, X: np.ndarray) -> np.ndarray:
    """Pixel positions of world points, one camera row per point.

    Parameters
    ----------
    intr : (n, 5) intrinsics ``f, cx, cy, k1, k2`` per observation.
    rv, t : (n, 3) rotation vector and translation (camera from world) per observation.
    X : (n, 3) world points.
    """
    xc = rotate(rv, X) + t
    z = xc[:, 2]
    u, v = xc[:, 0] / z, xc[:, 1] / z
    r2 = u * u + v * v
    d = 1 + intr[:, 3] * r2 + intr[:, 4] * r2 * r2
    return np.column_stack([intr[:, 0] * u * d + intr[:, 1], intr[:, 0] * v * d + intr[:, 2]])


def undistort_normalised(intr: np.ndarray, xy: np.ndarray, iterations: int = 20) -> np.ndarray:
    """Normalised image coordinates (u, v) of pixels (fixed-point inversion of the radial model).

    Parameters
    ----------
    intr : ndarray (n, 5) or (5,)
        Intrinsics ``f, cx, cy, k1, k2`` per pixel, or one set for all.
    xy : ndarray (n, 2)
        Pixel positions (px).
    iterations : int
        Fixed-point iterations.

    Returns
    -------
    ndarray (n, 2)
        Normalised coordinates ``u, v``.
    """
    intr = np.atleast_2d(intr)
    ud = (xy[:, 0] - intr[:, 1]) / intr[:, 0]
    vd = (xy[:, 1] - intr[:, 2]) / intr[:, 0]
    u, v = ud.copy(), vd.copy()
    for _ in range(iterations):
        r2 = u * u + v * v
        d = 1 + intr[:, 3] * r2 + intr[:, 4] * r2 * r2
        u, v = ud / d, vd / d
    return np.column_stack([u, v])


def camera_centres(rv: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Projection centres ``C = -Rᵀ t`` for (n, 3) rotation vectors and translations."""
    return -rotate(-rv, t)


def triangulate(
    intr: np.ndarray, rv: np.ndarray, t: np.ndarray, xy: np.ndarray, point_index: np.ndarray, n_points: int
) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares ray intersection of many points at once (midpoint method).

    Each observation ``k`` of point ``point_index[k]`` contributes a ray from its camera
    centre; the point minimising the squared perpendicular distances to its rays solves
    a 3×3 system. Vectorised: O(observations + points).

    Parameters
    ----------
    intr : ndarray (n_obs, 5)
        Intrinsics ``f, cx, cy, k1, k2`` of each observation's camera.
    rv, t : ndarray (n_obs, 3)
        Rotation vector and translation (camera from world) of each observation's image.
    xy : ndarray (n_obs, 2)
        Measured pixels (px).
    point_index : ndarray (n_obs,) int
        Point of each observation.
    n_points : int
        Number of points.

    Returns
    -------
    X : (n_points, 3) points (NaN where fewer than two rays or the rays are parallel).
    miss : (n_points,) RMS perpendicular ray distance (m) at the solution.
    """
    uv = undistort_normalised(intr, xy)
    d_cam = np.column_stack([uv, np.ones(len(uv))])
    d = rotate(-rv, d_cam)  # Rᵀ d
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    C = camera_centres(rv, t)
    P = np.eye(3)[None] - d[:, :, None] * d[:, None, :]
    A = np.zeros((n_points, 3, 3))
    b = np.zeros((n_points, 3))
    np.add.at(A, point_index, P)
    np.add.at(b, point_index, np.einsum("nij,nj->ni", P, C))
    count = np.bincount(point_index, minlength=n_points)
    X = np.full((n_points, 3), np.nan)
    ok = (count >= 2) & (np.linalg.cond(A) < 1e12)
    if ok.any():
        X[ok] = np.linalg.solve(A[ok], b[ok][:, :, None])[:, :, 0]
    r = X[point_index] - C
    perp = r - np.sum(r * d, axis=1, keepdims=True) * d
    ss = np.bincount(point_index, weights=np.sum(perp**2, axis=1), minlength=n_points)
    with np.errstate(invalid="ignore", divide="ignore"):
        miss = np.sqrt(ss / count)
    miss[~ok] = np.nan
    return X, miss


def triangulation_covariance(intr: np.ndarray, rv: np.ndarray, t: np.ndarray, X: np.ndarray, sigma_px: float) -> np.ndarray:
    """Covariance (3×3, m²) of a point intersected from its rays, from the image noise alone.

    First-order propagation of independent pixel noise ``sigma_px`` through the projection:
    ``Σ = σ² (JᵀJ)⁻¹`` with ``J`` the (2n × 3) Jacobian of the n projections of ``X``
    (central differences). It carries the ray geometry: a point seen from a short
    baseline is weak in depth, however many rays it has. The cameras are taken as exact.

    Parameters
    ----------
    intr, rv, t : (n, 5), (n, 3), (n, 3) intrinsics and pose of each observing image.
    X : (3,) the point.
    sigma_px : standard deviation of each pixel coordinate.

    Returns
    -------
    (3, 3) covariance; all NaN where fewer than two rays or the geometry is singular.
    """
    n = len(rv)
    if n < 2 or not np.all(np.isfinite(X)):
        return np.full((3, 3), np.nan)
    depth = np.median(np.abs((rotate(rv, np.repeat(X[None], n, 0)) + t)[:, 2]))
    h = 1e-6 * max(depth, 1.0)
    J = np.empty((2 * n, 3))
    for axis in range(3):
        step = np.zeros(3)
        step[axis] = h
        plus = project(intr, rv, t, np.repeat((X + step)[None], n, 0))
        minus = project(intr, rv, t, np.repeat((X - step)[None], n, 0))
        J[:, axis] = ((plus - minus) / (2 * h)).ravel()
    normal = J.T @ J
    if np.linalg.cond(normal) > 1e12:
        return np.full((3, 3), np.nan)
    return sigma_px**2 * np.linalg.inv(normal)
