"""Session-10 CPU work on kitegully.terrain.smoothing: the same values as the former numpy code.

The former helpers (main at 969daf7) are kept here verbatim as references: the one-pass
gradient and the reused padded FFT buffer must give bit-identical arrays, so every
product made with the smoothing (depth map, tracing surface, head maps) stays identical.
"""

import numpy as np
import pytest
import scipy.fft as sfft

from kitegully.terrain import smoothing as sm


def _former_gradient(z, axis, out):
    zz = np.asarray(z, dtype=np.float64)
    d = np.diff(zz, axis=axis)
    pad = [(0, 0), (0, 0)]
    pad[axis] = (1, 0)
    bwd = np.pad(d, pad, constant_values=np.nan)
    pad[axis] = (0, 1)
    fwd = np.pad(d, pad, constant_values=np.nan)
    cnt = np.isfinite(bwd).astype(np.float64) + np.isfinite(fwd)
    np.nan_to_num(bwd, copy=False, nan=0.0)
    np.nan_to_num(fwd, copy=False, nan=0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        np.divide(bwd + fwd, cnt, out=out)
    out[cnt == 0] = 0.0
    out[~np.isfinite(zz)] = 0.0
    return out


def _former_convolve_axis(a, kernel, axis, out, workers):
    n = a.shape[axis]
    radius = kernel.size // 2
    nfft = sfft.next_fast_len(n + 2 * radius, real=True)
    h = sm._transfer(kernel, nfft).astype(np.complex64 if out.dtype == np.float32 else np.complex128)
    other = a.shape[1 - axis]
    step = max(1, int(sm._BLOCK_BYTES // (2 * out.itemsize * (nfft // 2 + 1))))
    for s in range(0, other, step):
        e = min(other, s + step)
        if axis == 1:
            spec = sfft.rfft(np.asarray(a[s:e, :], dtype=out.dtype), n=nfft, axis=1, workers=workers)
            spec *= h[None, :]
            out[s:e, :] = sfft.irfft(spec, n=nfft, axis=1, workers=workers)[:, :n]
        else:
            spec = sfft.rfft(np.ascontiguousarray(a[:, s:e], dtype=out.dtype), n=nfft, axis=0, workers=workers)
            spec *= h[:, None]
            out[:, s:e] = sfft.irfft(spec, n=nfft, axis=0, workers=workers)[:n, :]


def _surface(shape, holes=True, seed=3):
    rng = np.random.default_rng(seed)
    r, c = np.mgrid[0 : shape[0], 0 : shape[1]]
    z = (150 + 0.03 * r - 0.01 * c + np.sin(c / 17.0) + 0.05 * rng.standard_normal(shape)).astype(np.float32)
    if holes:
        z[5:9, 7:20] = np.nan
        z[:, -3:] = np.nan
        z[rng.random(shape) < 0.01] = np.nan  # isolated cells: one-sided and zero gradients
    return z


@pytest.mark.parametrize("dtype_in", [np.float32, np.float64])
@pytest.mark.parametrize("dtype_out", [np.float32, np.float64])
@pytest.mark.parametrize("axis", [0, 1])
def test_gradient_equals_former(axis, dtype_out, dtype_in):
    z = _surface((61, 83)).astype(dtype_in)
    z[0, 0] = np.inf  # inf cells and neighbours follow np.nan_to_num as before
    got = sm._one_sided_gradient(z, axis, out=np.empty(z.shape, dtype_out))
    want = np.empty(z.shape, dtype_out)
    with np.errstate(over="ignore"):  # the cleaned inf (largest float64) overflows float32, as before
        want[...] = _former_gradient(z, axis, out=np.empty(z.shape))
    assert np.array_equal(got, want)
    assert np.count_nonzero(got) > 0.9 * got.size


@pytest.mark.parametrize("axis", [0, 1])
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_convolve_axis_equals_former(axis, dtype, monkeypatch):
    monkeypatch.setattr(sm, "_BLOCK_BYTES", 40_000)  # several blocks, the last one partial
    a = np.nan_to_num(_surface((97, 131)), nan=0.0).astype(dtype)
    k = sm.gaussian_kernel_1d(3.3)
    got, want = np.empty_like(a), np.empty_like(a)
    sm._convolve_axis(a, k, axis, got, 1)
    _former_convolve_axis(a, k, axis, want, 1)
    assert np.array_equal(got, want)


@pytest.mark.parametrize("shape", [(300, 257), (3, 20_001)])
def test_mean_of_full_grid_equals_mean_of_its_valid_cells(shape):
    z = _surface(shape, holes=False)
    assert np.mean(z, dtype=np.float64) == np.mean(z[np.isfinite(z)], dtype=np.float64)


def test_smoothing_of_a_plane_is_the_plane_at_edges_and_holes():
    # the edge correction still works end to end (exact on planes, up to float32 rounding)
    r, c = np.mgrid[0:80, 0:90]
    z = (100 + 0.02 * r + 0.05 * c).astype(np.float32)
    z[30:40, 30:45] = np.nan
    zs = sm.gaussian_smooth_fft(z, 6.0)
    ok = np.isfinite(z)
    assert np.nanmax(np.abs(zs[ok] - z[ok])) < 2e-4


@pytest.mark.parametrize("sigma", [2.5, 12.0, 30.0])
def test_edge_strips_equal_whole_grid_correction_within_float32_rounding(sigma):
    # no nodata: the edge correction is made in the edge strips only (4 radii <= 400 cells)
    z = _surface((400, 430), holes=False)
    z += (np.arange(430, dtype=np.float32) * 0.02)[None, :]  # a slope: the correction matters
    whole = sm.gaussian_smooth_fft(z, sigma, edge_strips=False)
    strips = sm.gaussian_smooth_fft(z, sigma)
    plain = sm.gaussian_smooth_fft(z, sigma, linear_edges=False)
    diff = np.abs(whole.astype(np.float64) - strips)
    # stated tolerance: 1e-4 m (a few float32 steps at ~150 m), in < 1 % of the cells
    assert diff.max() <= 1e-4
    assert np.count_nonzero(diff) < 0.01 * diff.size
    # and the correction was applied (it moves the edge cells, by up to decimetres)
    assert np.abs(plain.astype(np.float64) - strips).max() > 100 * max(diff.max(), 1e-6)


def test_edge_strips_exact_on_a_plane():
    r, c = np.mgrid[0:200, 0:220]
    z = (100 + 0.02 * r + 0.05 * c).astype(np.float32)
    zs = sm.gaussian_smooth_fft(z, 6.0)  # 4 radii = 96 cells: the strip path
    assert np.abs(zs.astype(np.float64) - z).max() < 2e-4
