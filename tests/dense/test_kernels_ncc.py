"""The rewritten resampling and NCC kernels (issue 21) equal their definitions.

``sample_stack`` shares the elevation-independent part of the projection between
candidates; it must equal projecting every candidate in full (:func:`_project`, then
:func:`_bilinear`) bit for bit. ``multiview_ncc_stack`` sums whole rows of windows at once;
it must equal a per-cell float64 evaluation of the mean pairwise NCC within float
tolerance, with the same usable-view counts.
"""

from __future__ import annotations

import numpy as np
import pytest
from numba import njit
from numba.typed import List

from kitegully.dense.kernels import _bilinear, _project, multiview_ncc_stack, sample_stack
from kitegully.seeds import rng_for


@njit(cache=False)
def _sample_reference(imgs, Rs, Cs, Ps, levels, xs, ys, base, dz, out):
    """Every candidate projected in full, one sample at a time (the kernel's definition)."""
    K, V, H, W = out.shape
    for i in range(H):
        for v in range(V):
            sc = 1.0 / (2.0 ** levels[v])
            for k in range(K):
                for j in range(W):
                    z = base[i, j] + k * dz
                    u, w, d = _project(Rs[v], Cs[v], Ps[v], xs[j], ys[i], z)
                    if d <= 0.0 or not np.isfinite(z):
                        out[k, v, i, j] = np.nan
                    else:
                        out[k, v, i, j] = _bilinear(imgs[v], (u + 0.5) * sc - 0.5, (w + 0.5) * sc - 0.5)


def _rotation(omega, phi, kappa):
    co, so, cp, sp, ck, sk = np.cos(omega), np.sin(omega), np.cos(phi), np.sin(phi), np.cos(kappa), np.sin(kappa)
    rx = np.array([[1, 0, 0], [0, co, -so], [0, so, co]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rz = np.array([[ck, -sk, 0], [sk, ck, 0], [0, 0, 1]])
    # camera looking down (z axis of the camera towards the ground)
    down = np.diag([1.0, -1.0, -1.0])
    return (rz @ ry @ rx @ down).T


def _views(rng, V):
    Rs = np.ascontiguousarray([_rotation(*rng.normal(0, 0.08, 3)) for _ in range(V)])
    Cs = np.column_stack([rng.uniform(-3, 3, V), rng.uniform(-3, 3, V), rng.uniform(18, 25, V)])
    Ps = np.column_stack([np.full(V, 300.0), np.full(V, 160.0), np.full(V, 120.0),
                          rng.normal(0, 0.05, V), rng.normal(0, 0.01, V)])
    imgs = List()
    levels = np.array([0, 1, 0, 2, 1][:V], np.int64)
    for lev in levels:
        imgs.append(rng.uniform(0, 255, (240 >> lev, 320 >> lev)).astype(np.float32))
    return imgs, Rs, Cs, Ps, levels


@pytest.mark.parametrize("K,H,W", [(1, 9, 11), (7, 24, 31)])
def test_sample_stack_bit_identical_to_full_projection(K, H, W):
    rng = rng_for(21, "test_dense", f"sample-{K}")
    imgs, Rs, Cs, Ps, levels = _views(rng, 5)
    xs = np.linspace(-9.0, 9.0, W)  # reaches beyond some frames: NaN samples
    ys = np.linspace(9.0, -9.0, H)
    base = rng.uniform(-1.0, 1.0, (H, W))
    base[0, :3] = np.nan  # no candidate
    base[1, 0] = 30.0  # above a camera: behind it
    out = np.empty((K, 5, H, W), np.float32)
    ref = np.empty_like(out)
    sample_stack(imgs, Rs, Cs, Ps, levels, xs, ys, base, 0.05, out)
    _sample_reference(imgs, Rs, Cs, Ps, levels, xs, ys, base, 0.05, ref)
    assert np.isnan(ref).any() and np.isfinite(ref).any()
    assert np.array_equal(out, ref, equal_nan=True)


def _ncc_reference(stack, half, min_std):
    """Mean pairwise NCC of the usable views per cell and candidate, float64, by definition."""
    K, V, H, W = stack.shape
    n = (2 * half + 1) ** 2
    score = np.full((K, H, W), np.nan)
    nviews = np.zeros((K, H, W), np.int64)
    for k in range(K):
        for i in range(half, H - half):
            for j in range(half, W - half):
                a = []
                for v in range(V):
                    win = stack[k, v, i - half:i + half + 1, j - half:j + half + 1].astype(np.float64).ravel()
                    if not np.isfinite(win).all():
                        continue
                    d = win - win.mean()
                    ss = float(d @ d)
                    if ss <= 0.0 or ss < n * min_std[v] ** 2:
                        continue
                    a.append(d / np.sqrt(ss))
                nviews[k, i, j] = len(a)
                if len(a) >= 2:
                    pairs = [float(a[p] @ a[q]) for p in range(len(a)) for q in range(p + 1, len(a))]
                    score[k, i, j] = np.mean(pairs)
    return score, nviews


@pytest.mark.parametrize("half", [1, 2])
def test_ncc_rows_equal_per_cell_definition(half):
    rng = rng_for(21, "test_dense", f"ncc-{half}")
    K, V, H, W = 3, 5, 14, 17
    common = rng.uniform(0, 255, (H, W))
    stack = np.empty((K, V, H, W), np.float32)
    for k in range(K):
        for v in range(V):
            stack[k, v] = common + rng.normal(0, 10 + 40 * k, (H, W))  # correlation falls with k
    stack[0, 1, 4, 6] = np.nan  # incomplete windows around it
    stack[:, 2, :, : W // 2] = np.nan  # a view covering half of the tile
    stack[1, 3, 2:9, 3:12] = 77.0  # textureless patch: fails the texture test
    stack[2, 4] = np.nan  # a view that sees nothing at this candidate
    min_std = np.array([1.0, 0.5, 1.0, 2.0, 1.0])
    score = np.empty((K, H, W), np.float32)
    nv = np.empty((K, H, W), np.int16)
    multiview_ncc_stack(stack, half, min_std, score, nv)
    ref, ref_nv = _ncc_reference(stack, half, min_std)
    assert np.array_equal(nv, ref_nv)
    assert np.array_equal(np.isnan(score), np.isnan(ref))
    assert (ref_nv < 2).any() and (ref_nv == 5).any() and (ref_nv == 4).any()
    np.testing.assert_allclose(score, ref, rtol=0, atol=2e-6)
    # the windows' correlations really differ between candidates (the test can fail)
    assert np.nanmean(score[0]) > np.nanmean(score[2]) + 0.2
