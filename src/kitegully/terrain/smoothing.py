"""Gaussian smoothing of a DEM by FFT convolution, with nodata handled by normalised convolution.

The 2-D Gaussian is separable, so the 2-D FFT convolution ``IFFT(FFT(Z)·FFT(G))`` is
computed as two passes of 1-D FFT convolutions (rows, then columns). The result is the
same as one 2-D FFT of the zero-padded grid, but each pass works on blocks of rows or
columns, so memory stays at a few copies of the DEM whatever its size.

Nodata (NaN) and the area outside the grid get weight 0: with ``w`` the valid mask,
``Zs = G*(Z·w) / G*w`` (normalised convolution). Each axis is zero-padded by the kernel
radius (``truncate`` σ, [I] 4σ by default), so there is no wrap-around and the borders
and holes do not pull the smoothed surface down as plain zero padding would.
"""

from __future__ import annotations

import logging

import numba
import numpy as np
import scipy.fft as sfft

log = logging.getLogger(__name__)

_BLOCK_BYTES = 64 * 2**20  # complex spectrum of one block of rows/columns


def gaussian_kernel_1d(sigma_cells: float, truncate: float = 4.0) -> np.ndarray:
    """Sampled 1-D Gaussian kernel of radius ``ceil(truncate·σ)``, normalised to sum 1.

    Parameters
    ----------
    sigma_cells : float
        Standard deviation in cells (> 0).
    truncate : float
        Kernel radius in standard deviations.
    """
    if not sigma_cells > 0:
        raise ValueError(f"sigma must be positive, got {sigma_cells}")
    radius = int(np.ceil(truncate * sigma_cells))
    x = np.arange(-radius, radius + 1, dtype=np.float64)
    k = np.exp(-0.5 * (x / sigma_cells) ** 2)
    return k / k.sum()


def _transfer(kernel: np.ndarray, nfft: int) -> np.ndarray:
    """rFFT of the kernel centred on index 0 (negative offsets wrapped to the end)."""
    radius = kernel.size // 2
    buf = np.zeros(nfft, dtype=np.float64)
    buf[: radius + 1] = kernel[radius:]
    buf[nfft - radius :] = kernel[:radius]
    return sfft.rfft(buf)


def _convolve_axis(a: np.ndarray, kernel: np.ndarray, axis: int, out: np.ndarray, workers: int) -> None:
    """Linear (zero-padded) convolution of ``a`` with ``kernel`` along ``axis`` into ``out``.

    Each block of rows (columns) is copied into a zero-padded buffer of the FFT length
    that is reused from block to block (only its first ``n`` entries are overwritten, so
    the padding stays zero): the same transform inputs as ``rfft(block, n=nfft)``, which
    pads each block in a fresh array, hence the same values.
    """
    n = a.shape[axis]
    radius = kernel.size // 2
    nfft = sfft.next_fast_len(n + 2 * radius, real=True)
    h = _transfer(kernel, nfft).astype(np.complex64 if out.dtype == np.float32 else np.complex128)
    other = a.shape[1 - axis]
    step = max(1, int(_BLOCK_BYTES // (2 * out.itemsize * (nfft // 2 + 1))))
    buf = None
    for s in range(0, other, step):
        e = min(other, s + step)
        if buf is None or (buf.shape[0] if axis == 1 else buf.shape[1]) != e - s:
            buf = np.zeros((e - s, nfft) if axis == 1 else (nfft, e - s), dtype=out.dtype)
        if axis == 1:
            buf[:, :n] = a[s:e, :]
            spec = sfft.rfft(buf, axis=1, workers=workers)
            spec *= h[None, :]
            out[s:e, :] = sfft.irfft(spec, n=nfft, axis=1, workers=workers)[:, :n]
        else:
            buf[:n, :] = a[:, s:e]
            spec = sfft.rfft(buf, axis=0, workers=workers)
            spec *= h[:, None]
            out[:, s:e] = sfft.irfft(spec, n=nfft, axis=0, workers=workers)[:n, :]
        del spec


@numba.njit(cache=True, nogil=True)
def _clean(v: float) -> float:
    """``np.nan_to_num`` of one float64: NaN -> 0, ±inf -> ±largest float64."""
    if v != v:
        return 0.0
    if v == np.inf:
        return 1.7976931348623157e308
    if v == -np.inf:
        return -1.7976931348623157e308
    return v


@numba.njit(cache=True, nogil=True)
def _gradient_into(z: np.ndarray, axis: int, out: np.ndarray) -> None:  # pragma: no cover - compiled
    """Per-cell gradient of ``z`` along ``axis`` into ``out`` (float32 or float64), in one pass.

    Central difference, one-sided next to NaN (or the edge), 0 where both neighbours are
    missing and on NaN cells. The same float64 operations as the former numpy version
    (differences of the float64 elevations, ``(bwd + fwd) / count``, NaN and inf cleaned as
    ``np.nan_to_num``), so the same values, without its seven full-size temporaries.
    """
    h, w = z.shape
    for i in range(h):
        for j in range(w):
            zc = np.float64(z[i, j])
            if not np.isfinite(zc):
                out[i, j] = 0.0
                continue
            if axis == 0:
                bwd = zc - np.float64(z[i - 1, j]) if i > 0 else np.nan
                fwd = np.float64(z[i + 1, j]) - zc if i < h - 1 else np.nan
            else:
                bwd = zc - np.float64(z[i, j - 1]) if j > 0 else np.nan
                fwd = np.float64(z[i, j + 1]) - zc if j < w - 1 else np.nan
            cnt = (1.0 if np.isfinite(bwd) else 0.0) + (1.0 if np.isfinite(fwd) else 0.0)
            if cnt == 0.0:
                out[i, j] = 0.0
            else:
                out[i, j] = (_clean(bwd) + _clean(fwd)) / cnt


def _one_sided_gradient(z: np.ndarray, axis: int, out: np.ndarray) -> np.ndarray:
    """Per-cell gradient along ``axis``: central difference, one-sided next to NaN, 0 if isolated.

    O(n), one pass (:func:`_gradient_into`); ``out`` may be float32 (the values are rounded
    from float64 once, as assigning the float64 gradient would).
    """
    z = np.asarray(z)
    if z.dtype not in (np.float32, np.float64):
        z = z.astype(np.float64)
    _gradient_into(z, axis, out)
    return out


def _conv2(a: np.ndarray, kernel: np.ndarray, work: np.ndarray, workers: int) -> np.ndarray:
    """Separable 2-D convolution of float64 ``a`` in place (``work``: scratch of the same shape)."""
    _convolve_axis(a, kernel, 1, work, workers)
    _convolve_axis(work, kernel, 0, a, workers)
    return a


def _correct_edge_strips(z: np.ndarray, zs: np.ndarray, den: np.ndarray, off: np.ndarray, kernel: np.ndarray,
                         axis: int, dtype, workers: int) -> None:
    """The edge correction ``zs −= (G*ĝ / den)·(x̄ − x)`` along ``axis`` of a grid without nodata, in its edge strips.

    The centroid offset ``off`` = x̄ − x is zero (up to FFT rounding, |off| < 1e-11 cell)
    wherever the kernel window lies inside the grid, i.e. beyond one kernel radius r from
    the two edges across ``axis``. Only the r rows (columns) at each edge are corrected,
    and their smoothed gradient needs the gradient within 2r of the edge only (the
    convolution reaches r), which needs the DEM within 2r + 1: two strips of 2r instead
    of two whole-grid 2-D convolutions. Mathematically the same correction (the kernel
    never reaches beyond the strip); the FFT of a strip rounds differently from that of
    the whole grid, so values differ in the float32 rounding (see ``edge_strips`` of
    :func:`gaussian_smooth_fft`). Skipping the interior leaves out terms below
    1e-11 m, far below float32's resolution of the result. O(r·L·log) for L cells along the edge.
    """
    n = z.shape[axis]
    r = kernel.size // 2
    for lo, hi in ((0, r), (n - r, n)):
        s0, s1 = max(0, lo - r), min(n, hi + r)  # gradient cells the smoothing of [lo, hi) reaches
        g0, g1 = max(0, s0 - 1), min(n, s1 + 1)  # DEM cells that gradient reads
        zsl = z[g0:g1] if axis == 0 else z[:, g0:g1]
        g = np.empty(zsl.shape, dtype=dtype)
        _one_sided_gradient(zsl, axis, out=g)
        g = np.ascontiguousarray(g[s0 - g0 : s1 - g0] if axis == 0 else g[:, s0 - g0 : s1 - g0])
        _conv2(g, kernel, np.empty_like(g), workers)
        cut = slice(lo - s0, hi - s0)
        a = g[cut] if axis == 0 else g[:, cut]
        sl = (slice(lo, hi), slice(None)) if axis == 0 else (slice(None), slice(lo, hi))
        with np.errstate(invalid="ignore", divide="ignore"):
            a /= den[sl]
        a *= off[lo:hi, None] if axis == 0 else off[None, lo:hi]
        with np.errstate(invalid="ignore"):
            zs[sl] -= a if a.dtype == np.float32 else a.astype(np.float32)


def gaussian_smooth_fft(
    z: np.ndarray,
    sigma_cells: float,
    truncate: float = 4.0,
    workers: int = 1,
    min_weight: float = 1e-3,
    linear_edges: bool = True,
    dtype: type = np.float32,
    edge_strips: bool = True,
) -> np.ndarray:
    """Smooth a DEM with a Gaussian by FFT convolution; NaN cells are ignored.

    Parameters
    ----------
    z : ndarray (H, W)
        Elevations; NaN marks nodata.
    sigma_cells : float
        Standard deviation of the Gaussian in cells (σ_m / cell size).
    truncate : float
        Kernel radius (and zero padding) in σ. [I] 4 σ.
    workers : int
        Threads for ``scipy.fft``.
    min_weight : float
        Cells whose normalised-convolution weight ``G*w`` is below this get NaN
        (too far from any valid cell).
    linear_edges : bool
        [I] First-order correction near edges and nodata. There the window is
        one-sided, so normalised convolution returns the elevation at the weighted
        centroid instead of at the cell: on a slope g the bias is ``g·(x̄ − x)`` (0.16 m
        at the edge of a 2 % slope with σ = 10 m, enough for a false gully). The
        correction subtracts ``ĝ·(x̄ − x)`` with ``ĝ`` the smoothed gradient of the DEM;
        it is exact on planes and zero where the window is full.
    edge_strips : bool
        With no nodata, compute the edge correction only in the strips where it is not
        zero (:func:`_correct_edge_strips`; grids at least 4 kernel radii across). It
        equals the whole-grid correction up to float32 rounding of the FFT sums: the
        smoothed surface differs by at most 1e-4 m, in < 1 % of the cells (within two
        float32 steps of an elevation of a few hundred metres; tested). ``False``: the
        whole-grid correction (session 9's values bit for bit).
    dtype : numpy float type
        Precision of the FFT work arrays. float32 (default) halves time and memory; on
        valid cells it differs from float64 by < 2e-5 m (the float32 resolution of
        elevations of a few hundred metres), since elevations are taken relative to
        their mean.

    Returns
    -------
    ndarray (H, W) float32
        The smoothed surface, defined also in small nodata holes.

    Notes
    -----
    Complexity O(n log n) for n = H·W cells. Memory: three work arrays of the
    grid size plus one block spectrum (64 MB). With no nodata the weight image and the
    centroids are separable and come from 1-D convolutions; the edge correction costs
    two more 2-D convolutions (gradient), or four with nodata. Each gradient is one
    compiled pass into the work array, and the FFT blocks reuse one zero-padded buffer
    (session 10: 1.3–1.6× less CPU at 20 M cells than the former numpy code, the same
    values bit for bit; ``tests/terrain/test_smoothing.py``).
    """
    z = np.asarray(z)
    if z.ndim != 2:
        raise ValueError("z must be a 2-D array")
    h, w = z.shape
    valid = np.isfinite(z)
    nvalid = int(np.count_nonzero(valid))
    if nvalid == 0:
        raise ValueError("the DEM has no valid cell")
    full = nvalid == z.size
    kernel = gaussian_kernel_1d(sigma_cells, truncate)
    # Work relative to the mean elevation: better precision of the FFT sums. (With no
    # nodata the mean of the C-contiguous grid is the mean of its valid cells, summed in
    # the same order: no copy of them; tested.)
    offset = float(np.mean(z if full and z.flags.c_contiguous else z[valid], dtype=np.float64))
    if full:
        valid = None
    # z − offset in z's precision, zero on nodata, as np.where(valid, z − offset, 0) did
    a = z - offset
    if valid is not None:
        a[~valid] = 0.0
    if a.dtype != dtype:
        a = a.astype(dtype)
    work = np.empty((h, w), dtype=dtype)
    _conv2(a, kernel, work, workers)
    if full:
        wr = np.empty((1, w))
        wc = np.empty((h, 1))
        _convolve_axis(np.ones((1, w)), kernel, 1, wr, workers)
        _convolve_axis(np.ones((h, 1)), kernel, 0, wc, workers)
        den = np.empty((h, w), dtype=dtype)
        np.multiply(wc, wr, out=den)  # separable weight image (float64 product, rounded once)
    else:
        den = _conv2(valid.astype(dtype), kernel, work, workers)
    with np.errstate(invalid="ignore", divide="ignore"):
        zs = a / den
    if zs.dtype != np.float32:
        zs = zs.astype(np.float32)
    if linear_edges:
        # Smoothed gradient of the DEM (per cell), zero where a neighbour is missing.
        for axis in (0, 1):
            n = h if axis == 0 else w
            radius = kernel.size // 2
            if full:
                # Centroid offset (x̄ − x) along this axis, in cells: separable, 1-D.
                idx = np.arange(n, dtype=np.float64)
                num1 = np.empty(n)
                wt1 = np.empty(n)
                _convolve_axis(idx[None, :], kernel, 1, num1[None, :], workers)
                _convolve_axis(np.ones((1, n)), kernel, 1, wt1[None, :], workers)
                off = num1 / wt1 - idx
                if edge_strips and 4 * radius <= n:
                    _correct_edge_strips(z, zs, den, off, kernel, axis, dtype, workers)
                    continue
            _one_sided_gradient(z, axis, out=a)
            _conv2(a, kernel, work, workers)
            with np.errstate(invalid="ignore", divide="ignore"):
                a /= den
            if full:
                a *= off[:, None] if axis == 0 else off[None, :]
            else:
                idx = np.arange(n, dtype=np.float64)
                coord = np.broadcast_to(idx[:, None] if axis == 0 else idx[None, :], (h, w))
                c = np.where(valid, coord, 0.0).astype(dtype)
                _conv2(c, kernel, work, workers)
                with np.errstate(invalid="ignore", divide="ignore"):
                    c /= den
                c -= coord
                a *= c
                del c
            with np.errstate(invalid="ignore"):
                zs -= a if a.dtype == np.float32 else a.astype(np.float32)
    del a, work
    if not np.min(den) >= min_weight:  # NaN-safe: a NaN weight also blanks its cell
        zs[~(den >= min_weight)] = np.nan
    zs += np.float32(offset)
    return zs
