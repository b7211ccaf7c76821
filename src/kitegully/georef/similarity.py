"""Seven-parameter similarity transforms and the tape-distance + Horn variant (paper 004).

A similarity maps model points ``a`` to world points ``b = s R a + t``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kitegully import InputError


@dataclass
class Similarity:
    """``b = scale * R @ a + t``."""

    scale: float
    R: np.ndarray
    t: np.ndarray

    def apply(self, a: np.ndarray) -> np.ndarray:
        """Transform points ``a`` (N × 3): ``scale · R a + t``."""
        return self.scale * np.asarray(a) @ self.R.T + self.t

    def as_dict(self) -> dict:
        """Scale, rotation matrix (nested lists) and translation (m) as a JSON-ready dict."""
        return {"scale": float(self.scale), "rotation": self.R.tolist(), "translation_m": self.t.tolist()}


def umeyama(a: np.ndarray, b: np.ndarray, with_scale: bool = True, weights: np.ndarray | None = None) -> Similarity:
    """Least-squares similarity (Umeyama 1991; Horn's closed form via SVD). O(n).

    Parameters
    ----------
    a, b : (n, 3) corresponding model and world points, n ≥ 3 not collinear.
    with_scale : estimate the scale (False: rigid motion, scale 1).
    weights : optional (n,) non-negative weights.
    """
    a, b = np.asarray(a, float), np.asarray(b, float)
    if len(a) < 3:
        raise InputError(f"a similarity transform needs at least 3 points, got {len(a)}")
    w = np.ones(len(a)) if weights is None else np.asarray(weights, float)
    w = w / w.sum()
    ma, mb = w @ a, w @ b
    A, B = a - ma, b - mb
    S = (B * w[:, None]).T @ A
    U, D, Vt = np.linalg.svd(S)
    E = np.eye(3)
    if np.linalg.det(U) * np.linalg.det(Vt) < 0:
        E[2, 2] = -1
    R = U @ E @ Vt
    var_a = float(np.sum(w * np.sum(A * A, axis=1)))
    if var_a <= 0 or D[1] < 1e-12 * max(D[0], 1e-300):
        raise InputError("the GCPs are (nearly) collinear; a similarity transform is undetermined")
    s = float(np.trace(np.diag(D) @ E) / var_a) if with_scale else 1.0
    t = mb - s * R @ ma
    return Similarity(s, R, t)


def level_rotation(down: np.ndarray) -> np.ndarray:
    """The smallest rotation taking the direction ``down`` (3,) onto ``(0, 0, -1)``.

    Parameters
    ----------
    down : (3,) array
        A direction in the source frame (need not be unit length).

    Returns
    -------
    (3, 3) array
        Rotation matrix ``R`` with ``R @ down / |down| = (0, 0, -1)``.
    """
    d = np.asarray(down, float)
    d = d / np.linalg.norm(d)
    target = np.array([0.0, 0.0, -1.0])
    v = np.cross(d, target)
    c = float(d @ target)
    if np.linalg.norm(v) < 1e-12:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    vx = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + vx + vx @ vx / (1.0 + c)


def plan_similarity(a: np.ndarray, b_xy: np.ndarray, down: np.ndarray, z0: float = 0.0) -> Similarity:
    """Similarity from plan coordinates only: levelled by ``down``, fitted in x and y. O(n).

    For ground control whose heights are unknown (placeholders): the model is first
    rotated so that ``down`` points to -z, then scale, rotation about the vertical and the
    horizontal shift are fitted to the points' plan coordinates by least squares (2-D
    Procrustes); the vertical shift puts the points' median height at ``z0``. Heights of
    the result are therefore relative, with a tilt as good as ``down``.

    Parameters
    ----------
    a : (n, 3) array
        Model points, n >= 2 and not all at one plan position.
    b_xy : (n, 2) array
        Their plan coordinates in the target frame (m).
    down : (3,) array
        The vertical (downwards) direction in the model frame.
    z0 : float
        Height given to the points' median (the placeholder height of the file).

    Returns
    -------
    Similarity
        ``b = scale * R @ a + t``.
    """
    a, b = np.asarray(a, float), np.asarray(b_xy, float)
    if len(a) < 2:
        raise InputError(f"a plan-only similarity needs at least 2 points, got {len(a)}")
    R0 = level_rotation(down)
    al = a @ R0.T
    ma, mb = al[:, :2].mean(axis=0), b.mean(axis=0)
    A, B = al[:, :2] - ma, b - mb
    var_a = float(np.sum(A * A))
    if var_a <= 0 or float(np.sum(B * B)) <= 0:
        raise InputError("the GCPs share one plan position; a plan-only similarity is undetermined")
    U, D, Vt = np.linalg.svd(B.T @ A)
    E = np.diag([1.0, np.sign(np.linalg.det(U) * np.linalg.det(Vt)) or 1.0])
    R2 = U @ E @ Vt
    s = float(np.trace(np.diag(D) @ E) / var_a)
    Rz = np.eye(3)
    Rz[:2, :2] = R2
    R = Rz @ R0
    t = np.zeros(3)
    t[:2] = mb - s * R2 @ ma
    t[2] = z0 - s * float(np.median(al[:, 2]))
    return Similarity(s, R, t)


def horn_quaternion(a: np.ndarray, b: np.ndarray) -> Similarity:
    """Horn's (1987) quaternion absolute orientation, rotation and translation only.

    The points ``a`` must already be scaled (paper 004 scales the model from taped
    distances first). ``S_uv = Σ a'_u b'_v`` over centred points builds Horn's symmetric
    4×4 matrix N; its top eigenvector is the rotation quaternion. O(n).
    """
    a, b = np.asarray(a, float), np.asarray(b, float)
    if len(a) < 3:
        raise InputError(f"Horn's method needs at least 3 points, got {len(a)}")
    ma, mb = a.mean(0), b.mean(0)
    S = (a - ma).T @ (b - mb)
    Sxx, Sxy, Sxz = S[0]
    Syx, Syy, Syz = S[1]
    Szx, Szy, Szz = S[2]
    N = np.array(
        [
            [Sxx + Syy + Szz, Syz - Szy, Szx - Sxz, Sxy - Syx],
            [Syz - Szy, Sxx - Syy - Szz, Sxy + Syx, Szx + Sxz],
            [Szx - Sxz, Sxy + Syx, -Sxx + Syy - Szz, Syz + Szy],
            [Sxy - Syx, Szx + Sxz, Syz + Szy, -Sxx - Syy + Szz],
        ]
    )
    vals, vecs = np.linalg.eigh(N)
    w, x, y, z = vecs[:, np.argmax(vals)]
    R = np.array(
        [
            [w * w + x * x - y * y - z * z, 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), w * w - x * x + y * y - z * z, 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), w * w - x * x - y * y + z * z],
        ]
    )
    t = mb - R @ ma
    return Similarity(1.0, R, t)


def tape_scale(model_xyz: dict[str, np.ndarray], edges: list[tuple[str, str, float]]) -> tuple[float, np.ndarray]:
    """Model scale from taped distances: ``s = mean_k(d_tape_k / d_model_k)`` (paper 004, [I] mean of ratios).

    Returns the scale and the per-edge ratios. Edges with a marker absent from the model
    are skipped; none left is an InputError.
    """
    ratios = []
    for a, b, d in edges:
        if a in model_xyz and b in model_xyz:
            dm = float(np.linalg.norm(model_xyz[a] - model_xyz[b]))
            if dm > 0:
                ratios.append(d / dm)
    if not ratios:
        raise InputError("no taped distance joins two triangulated GCPs; cannot scale the model")
    r = np.array(ratios)
    return float(r.mean()), r


def tape_horn(model_xyz: dict[str, np.ndarray], gps_xyz: dict[str, np.ndarray], edges: list[tuple[str, str, float]]) -> Similarity:
    """Paper 004's low-cost georeferencing: tape-distance scale, then Horn on GPS positions.

    Parameters
    ----------
    model_xyz : dict of str to ndarray (3,)
        Triangulated GCP positions in the model frame, by GCP id.
    gps_xyz : dict of str to ndarray (3,)
        GPS positions of the GCPs in the target frame (m), by GCP id.
    edges : list of (str, str, float)
        Taped distances ``(gcp_a, gcp_b, m)``.

    Returns
    -------
    Similarity
        The tape scale with Horn's rotation and translation, fitted on the GCPs in both mappings.
    """
    s, _ = tape_scale(model_xyz, edges)
    ids = [k for k in model_xyz if k in gps_xyz]
    a = np.array([model_xyz[k] for k in ids]) * s
    b = np.array([gps_xyz[k] for k in ids])
    rigid = horn_quaternion(a, b)
    return Similarity(s, rigid.R, rigid.t)


def loo_residuals(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Leave-one-out residual vectors: each point predicted by a fit to the others. O(n²)."""
    n = len(a)
    out = np.full((n, 3), np.nan)
    if n < 4:
        return out
    for i in range(n):
        keep = np.arange(n) != i
        out[i] = umeyama(a[keep], b[keep]).apply(a[i : i + 1])[0] - b[i]
    return out


def robust_similarity(a: np.ndarray, b: np.ndarray, max_residual_m: float, min_points: int = 3) -> tuple[Similarity, np.ndarray]:
    """Similarity that leaves out a point which disagrees with the rest.

    Repeatedly: fit all remaining points; if the worst residual exceeds
    ``max_residual_m`` and a fit without that point brings every other residual within
    ``max_residual_m``, the point spoils the solution and is dropped. If no single point
    explains the misfit (the set is inconsistent as a whole) nothing is dropped; the
    caller reports the misfit. Stops at ``min_points``. O(n²) for n GCPs.

    Parameters
    ----------
    a, b : ndarray (n, 3)
        Corresponding model and world points (``b`` in m).
    max_residual_m : float
        Largest residual a point may keep (m).
    min_points : int
        No point is dropped once this many are left.

    Returns
    -------
    sim : Similarity
        The least-squares similarity of the kept points.
    inliers : ndarray (n,) bool
        True for the kept points.
    """
    inl = np.ones(len(a), bool)
    while inl.sum() > min_points:
        idx = np.flatnonzero(inl)
        r = np.linalg.norm(umeyama(a[idx], b[idx]).apply(a[idx]) - b[idx], axis=1)
        worst = int(np.argmax(r))
        if r[worst] <= max_residual_m:
            break
        rest = np.delete(idx, worst)
        r_rest = np.linalg.norm(umeyama(a[rest], b[rest]).apply(a[rest]) - b[rest], axis=1)
        if np.max(r_rest) > max_residual_m:
            break
        inl[idx[worst]] = False
    return umeyama(a[inl], b[inl]), inl
