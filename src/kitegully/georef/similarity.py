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
        return self.scale * np.asarray(a) @ self.R.T + self.t

    def as_dict(self) -> dict:
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
    """Paper 004's low-cost georeferencing: tape-distance scale, then Horn on GPS positions."""
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
