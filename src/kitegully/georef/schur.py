"""Compiled kernels of the GCP bundle's normal equations and their Schur complement.

The bundle's unknowns are P camera parameters (refined intrinsics and poses) and N
points. Each observation ``o`` of point ``p`` contributes a 2 × 11 camera Jacobian
``Jc[o]`` (5 intrinsics then 6 pose columns, weighted) and a 2 × 3 point Jacobian
``Jx[o]``; ``ci[o]`` holds the global index of each of the 11 camera columns, −1 where the
column is not an unknown (an intrinsic that is not refined).

With ``W_o = Jc[o]ᵀ Jx[o]`` (11 × 3) and the damped 3 × 3 point blocks ``V_p``, the reduced
camera system is ``S = U − Σ_p Σ_{o,o' ∈ p} W_o V_p⁻¹ W_o'ᵀ``. SciPy's sparse product
``W V⁻¹ Wᵀ`` forms it through a P × 3N matrix with 33 entries per observation; these
kernels accumulate it point by point instead, with no per-observation matrices kept
(session 22: 7–11× faster per Levenberg–Marquardt iteration on a 528-photo block,
``benchmarks/bundle_speed.py``).

Observations are visited point by point through ``order`` (observation indices sorted by
point) and ``start`` (``order[start[p]:start[p + 1]]`` are point ``p``'s observations).
"""

from __future__ import annotations

import numpy as np
from numba import get_num_threads, njit, prange


def chunk_count(n_cam: int, max_bytes: float = 1e9) -> int:
    """Parallel chunks for the camera-block kernels: numba's threads, capped so that their
    private P × P sums stay under ``max_bytes``."""
    return int(max(1, min(get_num_threads(), max_bytes // (8.0 * n_cam * n_cam))))


def point_order(o_pt: np.ndarray, n_points: int) -> tuple[np.ndarray, np.ndarray]:
    """Observations grouped by point: ``order`` and the CSR offsets ``start`` (n_points + 1)."""
    order = np.argsort(o_pt, kind="stable")
    start = np.zeros(n_points + 1, dtype=np.int64)
    np.cumsum(np.bincount(o_pt, minlength=n_points), out=start[1:])
    return order.astype(np.int64), start


@njit(cache=True)
def _rotate(r0, r1, r2, x0, x1, x2):
    """Rodrigues rotation of one point (as :func:`kitegully.georef.geometry.rotate`)."""
    theta = np.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
    if theta > 1e-12:
        k0, k1, k2 = r0 / theta, r1 / theta, r2 / theta
    else:
        k0, k1, k2 = 0.0, 0.0, 0.0
    c, s = np.cos(theta), np.sin(theta)
    kd = (k0 * x0 + k1 * x1 + k2 * x2) * (1 - c)
    return (x0 * c + (k1 * x2 - k2 * x1) * s + k0 * kd,
            x1 * c + (k2 * x0 - k0 * x2) * s + k1 * kd,
            x2 * c + (k0 * x1 - k1 * x0) * s + k2 * kd)


@njit(parallel=True, cache=True)
def weighted_jacobians(intr: np.ndarray, cam: np.ndarray, rv: np.ndarray, t: np.ndarray, o_img: np.ndarray,
                       pts: np.ndarray, o_pt: np.ndarray, weight: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Camera and point Jacobians of every observation's pixel, times ``weight``.

    The same derivatives as :func:`kitegully.georef.bundle.projection_jacobian` (analytic
    except the rotation columns, central differences with h = 1e-6), one observation at a
    time without the NumPy version's (n, ...) temporaries.

    Parameters
    ----------
    intr : (n_cameras, 5) intrinsics; cam : (n,) camera of each observation.
    rv, t : (n_images, 3) poses; o_img : (n,) image of each observation.
    pts : (N, 3) points; o_pt : (n,) point of each observation.
    weight : (n,) row weight (√Huber weight / σ).

    Returns
    -------
    Jc : (n, 2, 11) (f, cx, cy, k1, k2, rotation vector, translation) and Jx : (n, 2, 3).
    O(n) time.
    """
    n = len(o_img)
    Jc = np.empty((n, 2, 11))
    Jx = np.empty((n, 2, 3))
    h = 1e-6
    for o in prange(n):
        c, i, p = cam[o], o_img[o], o_pt[o]
        f, k1, k2 = intr[c, 0], intr[c, 3], intr[c, 4]
        r0, r1, r2 = rv[i, 0], rv[i, 1], rv[i, 2]
        X0, X1, X2 = pts[p, 0], pts[p, 1], pts[p, 2]
        a0, a1, a2 = _rotate(r0, r1, r2, X0, X1, X2)
        xc0, xc1, xc2 = a0 + t[i, 0], a1 + t[i, 1], a2 + t[i, 2]
        u, v = xc0 / xc2, xc1 / xc2
        rho = u * u + v * v
        d = 1 + k1 * rho + k2 * rho * rho
        dd = k1 + 2 * k2 * rho
        w = weight[o]
        Jc[o, 0, 0], Jc[o, 1, 0] = w * u * d, w * v * d
        Jc[o, 0, 1], Jc[o, 1, 1] = w, 0.0
        Jc[o, 0, 2], Jc[o, 1, 2] = 0.0, w
        Jc[o, 0, 3], Jc[o, 1, 3] = w * f * u * rho, w * f * v * rho
        Jc[o, 0, 4], Jc[o, 1, 4] = w * f * u * rho * rho, w * f * v * rho * rho
        # d pixel / d (u, v) times d (u, v) / d xc
        A00 = f * (d + 2 * u * u * dd)
        A01 = f * 2 * u * v * dd
        A11 = f * (d + 2 * v * v * dd)
        iz = 1 / xc2
        B0 = (iz, 0.0, -u * iz)
        B1 = (0.0, iz, -v * iz)
        J0 = (A00 * B0[0] + A01 * B1[0], A00 * B0[1] + A01 * B1[1], A00 * B0[2] + A01 * B1[2])
        J1 = (A01 * B0[0] + A11 * B1[0], A01 * B0[1] + A11 * B1[1], A01 * B0[2] + A11 * B1[2])
        for k in range(3):
            Jc[o, 0, 8 + k], Jc[o, 1, 8 + k] = w * J0[k], w * J1[k]
        # rotation columns: central differences of R(rv) X
        for k in range(3):
            e0, e1, e2 = h if k == 0 else 0.0, h if k == 1 else 0.0, h if k == 2 else 0.0
            p0, p1, p2 = _rotate(r0 + e0, r1 + e1, r2 + e2, X0, X1, X2)
            m0, m1, m2 = _rotate(r0 - e0, r1 - e1, r2 - e2, X0, X1, X2)
            d0, d1, d2 = (p0 - m0) / (2 * h), (p1 - m1) / (2 * h), (p2 - m2) / (2 * h)
            Jc[o, 0, 5 + k] = w * (J0[0] * d0 + J0[1] * d1 + J0[2] * d2)
            Jc[o, 1, 5 + k] = w * (J1[0] * d0 + J1[1] * d1 + J1[2] * d2)
        # d xc / d X = R: its columns are the rotated unit vectors
        for k in range(3):
            c0, c1, c2 = _rotate(r0, r1, r2, 1.0 if k == 0 else 0.0, 1.0 if k == 1 else 0.0, 1.0 if k == 2 else 0.0)
            Jx[o, 0, k] = w * (J0[0] * c0 + J0[1] * c1 + J0[2] * c2)
            Jx[o, 1, k] = w * (J1[0] * c0 + J1[1] * c1 + J1[2] * c2)
    return Jc, Jx


@njit(cache=True)
def _chunks(start, n_chunks):
    """Point ranges of ``n_chunks`` chunks with about equal numbers of observations."""
    n_points = len(start) - 1
    bounds = np.empty(n_chunks + 1, dtype=np.int64)
    bounds[0] = 0
    for c in range(1, n_chunks):
        bounds[c] = np.searchsorted(start, start[-1] * c // n_chunks)
    bounds[n_chunks] = n_points
    for c in range(1, n_chunks + 1):
        bounds[c] = min(max(bounds[c], bounds[c - 1]), n_points)
    return bounds


@njit(parallel=True, cache=True)
def accumulate_normal_equations(Jc: np.ndarray, Jx: np.ndarray, rr: np.ndarray, ci: np.ndarray, order: np.ndarray,
                                start: np.ndarray, n_cam: int,
                                n_chunks: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Gauss–Newton blocks of the weighted Jacobian.

    Parameters
    ----------
    Jc : (n, 2, 11) weighted camera Jacobians (columns with ``ci < 0`` are ignored).
    Jx : (n, 2, 3) weighted point Jacobians.
    rr : (n, 2) weighted residuals.
    ci : (n, 11) global camera-parameter index of each column, −1 for none.
    order, start : observations grouped by point (:func:`point_order`).
    n_cam : P.
    n_chunks : point chunks run in parallel, each with its own P × P camera block.

    Returns
    -------
    U : (P, P) camera block JcᵀJc; V : (N, 3, 3) point blocks JxᵀJx; gc : (P,) and
    gp : (N, 3) gradients Jᵀr.

    Notes
    -----
    O(n · 11²) time, O(n_chunks · P² + N) memory.
    """
    n_points = len(start) - 1
    Uc = np.zeros((n_chunks, n_cam, n_cam))
    gcc = np.zeros((n_chunks, n_cam))
    V = np.zeros((n_points, 3, 3))
    gp = np.zeros((n_points, 3))
    bounds = _chunks(start, n_chunks)
    for c in prange(n_chunks):
        for p in range(bounds[c], bounds[c + 1]):
            for q in range(start[p], start[p + 1]):
                o = order[q]
                for a in range(11):
                    ca = ci[o, a]
                    if ca < 0:
                        continue
                    gcc[c, ca] += Jc[o, 0, a] * rr[o, 0] + Jc[o, 1, a] * rr[o, 1]
                    for b in range(11):
                        cb = ci[o, b]
                        if cb >= 0:
                            Uc[c, ca, cb] += Jc[o, 0, a] * Jc[o, 0, b] + Jc[o, 1, a] * Jc[o, 1, b]
                for i in range(3):
                    gp[p, i] += Jx[o, 0, i] * rr[o, 0] + Jx[o, 1, i] * rr[o, 1]
                    for j in range(3):
                        V[p, i, j] += Jx[o, 0, i] * Jx[o, 0, j] + Jx[o, 1, i] * Jx[o, 1, j]
    return _sum_chunks(Uc), V, _sum_chunks(gcc), gp


@njit(parallel=True, cache=True)
def _sum_chunks(a):
    """Sum over the first axis (the chunks' private copies), in parallel over rows."""
    out = np.zeros(a.shape[1:])
    for r in prange(a.shape[1]):
        for c in range(a.shape[0]):
            out[r] += a[c, r]
    return out


@njit(parallel=True, cache=True)
def reduce_to_cameras(Jc: np.ndarray, Jx: np.ndarray, ci: np.ndarray, order: np.ndarray, start: np.ndarray,
                      Vinv: np.ndarray, gp: np.ndarray, n_cam: int, n_chunks: int) -> tuple[np.ndarray, np.ndarray]:
    """The points' share of the reduced camera system and of its right-hand side.

    Parameters
    ----------
    Jc, Jx, ci : as in :func:`accumulate_normal_equations`.
    order, start : observations grouped by point (:func:`point_order`).
    Vinv : (N, 3, 3) inverses (or pseudo-inverses) of the damped point blocks.
    gp : (N, 3) point gradients.
    n_cam : P.
    n_chunks : point chunks run in parallel, each with its own P × P sum.

    Returns
    -------
    WVW : (P, P) ``Σ_p W_p V_p⁻¹ W_pᵀ``, so that ``S = U_damped − WVW``.
    WVg : (P,) ``Σ_p W_p V_p⁻¹ g_p``, so that the right-hand side is ``−gc + WVg``.

    Notes
    -----
    O(Σ_p m_p (m_p + 1) / 2 · 11² · 3) time for tracks of m_p observations,
    O(n_chunks · P²) memory.
    """
    n_points = len(start) - 1
    m_max = 0
    for p in range(n_points):
        m_max = max(m_max, start[p + 1] - start[p])
    WVWc = np.zeros((n_chunks, n_cam, n_cam))
    WVgc = np.zeros((n_chunks, n_cam))
    bounds = _chunks(start, n_chunks)
    for c in prange(n_chunks):
        W = np.empty((m_max, 11, 3))
        Y = np.empty((m_max, 11, 3))
        WVW = WVWc[c]
        WVg = WVgc[c]
        for p in range(bounds[c], bounds[c + 1]):
            o0 = start[p]
            m = start[p + 1] - o0
            for j in range(m):
                o = order[o0 + j]
                for a in range(11):
                    for k in range(3):
                        W[j, a, k] = Jc[o, 0, a] * Jx[o, 0, k] + Jc[o, 1, a] * Jx[o, 1, k]
                for a in range(11):
                    for k in range(3):
                        Y[j, a, k] = W[j, a, 0] * Vinv[p, 0, k] + W[j, a, 1] * Vinv[p, 1, k] + W[j, a, 2] * Vinv[p, 2, k]
                    ca = ci[o, a]
                    if ca >= 0:
                        WVg[ca] += Y[j, a, 0] * gp[p, 0] + Y[j, a, 1] * gp[p, 1] + Y[j, a, 2] * gp[p, 2]
            # pairs (j, l) with l >= j; the (l, j) block is the transpose of the (j, l) one
            for j in range(m):
                oj = order[o0 + j]
                for l in range(j, m):
                    ol = order[o0 + l]
                    for a in range(11):
                        ca = ci[oj, a]
                        if ca < 0:
                            continue
                        for b in range(11):
                            cb = ci[ol, b]
                            if cb >= 0:
                                v = Y[j, a, 0] * W[l, b, 0] + Y[j, a, 1] * W[l, b, 1] + Y[j, a, 2] * W[l, b, 2]
                                WVW[ca, cb] += v
                                if l != j:
                                    WVW[cb, ca] += v
    return _sum_chunks(WVWc), _sum_chunks(WVgc)


@njit(parallel=True, cache=True)
def point_steps(Jc: np.ndarray, Jx: np.ndarray, ci: np.ndarray, order: np.ndarray, start: np.ndarray,
                Vinv: np.ndarray, gp: np.ndarray, dc: np.ndarray) -> np.ndarray:
    """Point updates after the camera update ``dc``: ``dp_p = −V_p⁻¹ (g_p + W_pᵀ dc)``.

    Parameters
    ----------
    Jc, Jx, ci, order, start : as in :func:`accumulate_normal_equations`.
    Vinv : (N, 3, 3) inverses of the damped point blocks.
    gp : (N, 3) point gradients.
    dc : (P,) camera update.

    Returns
    -------
    dp : (N, 3). O(n · 11 · 3) time.
    """
    n_points = Vinv.shape[0]
    dp = np.empty((n_points, 3))
    for p in prange(n_points):
        q0, q1, q2 = gp[p, 0], gp[p, 1], gp[p, 2]
        for j in range(start[p], start[p + 1]):
            o = order[j]
            v0 = 0.0
            v1 = 0.0
            for a in range(11):
                ca = ci[o, a]
                if ca >= 0:
                    v0 += Jc[o, 0, a] * dc[ca]
                    v1 += Jc[o, 1, a] * dc[ca]
            q0 += Jx[o, 0, 0] * v0 + Jx[o, 1, 0] * v1
            q1 += Jx[o, 0, 1] * v0 + Jx[o, 1, 1] * v1
            q2 += Jx[o, 0, 2] * v0 + Jx[o, 1, 2] * v1
        for k in range(3):
            dp[p, k] = -(Vinv[p, k, 0] * q0 + Vinv[p, k, 1] * q1 + Vinv[p, k, 2] * q2)
    return dp
