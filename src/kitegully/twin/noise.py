"""Hash-based fractal value noise, evaluated anywhere without state.

Every value depends only on the map coordinate and a seed, never on the tile being
computed, so a raster generated tile by tile is identical to one generated in one piece.
The kernels are compiled with numba (``cache=True``) and parallel over rows.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

_MASK = 0xFFFFFFFF


@njit(cache=True, inline="always")
def _lattice(ix: np.int64, iy: np.int64, seed: np.int64) -> float:
    """Pseudo-random value in [-1, 1] for an integer lattice node (integer mixing hash)."""
    h = ((ix & _MASK) * np.int64(0x27D4EB2D)) ^ ((iy & _MASK) * np.int64(0x165667B1)) ^ ((seed & 0x7FFFFFFF) * np.int64(0x3C6EF372))
    h = h & _MASK
    h = ((h ^ (h >> 15)) * np.int64(0x2C1B3C6D)) & _MASK
    h = ((h ^ (h >> 12)) * np.int64(0x297A2D39)) & _MASK
    h = h ^ (h >> 15)
    return h * (2.0 / 4294967295.0) - 1.0


@njit(cache=True, inline="always")
def _value_noise(x: float, y: float, seed: np.int64) -> float:
    """Value noise with quintic fade at (x, y) in lattice units; range [-1, 1]."""
    fx = np.floor(x)
    fy = np.floor(y)
    ix = np.int64(fx)
    iy = np.int64(fy)
    tx = x - fx
    ty = y - fy
    sx = tx * tx * tx * (tx * (tx * 6.0 - 15.0) + 10.0)
    sy = ty * ty * ty * (ty * (ty * 6.0 - 15.0) + 10.0)
    a = _lattice(ix, iy, seed)
    b = _lattice(ix + 1, iy, seed)
    c = _lattice(ix, iy + 1, seed)
    d = _lattice(ix + 1, iy + 1, seed)
    return a + (b - a) * sx + (c - a) * sy + (a - b - c + d) * sx * sy


@njit(cache=True, parallel=True)
def _fbm_grid(xs, ys, seed, wavelengths, amplitudes, out):
    n_oct = wavelengths.size
    for i in prange(ys.size):
        for j in range(xs.size):
            s = 0.0
            for o in range(n_oct):
                inv = 1.0 / wavelengths[o]
                s += amplitudes[o] * _value_noise(xs[j] * inv + 0.37 * o, ys[i] * inv + 0.71 * o, seed + 7919 * o)
            out[i, j] += s


@njit(cache=True, parallel=True)
def _fbm_points(xs, ys, seed, wavelengths, amplitudes, out):
    n_oct = wavelengths.size
    for i in prange(xs.size):
        s = 0.0
        for o in range(n_oct):
            inv = 1.0 / wavelengths[o]
            s += amplitudes[o] * _value_noise(xs[i] * inv + 0.37 * o, ys[i] * inv + 0.71 * o, seed + 7919 * o)
        out[i] += s


def octaves(amplitude: float, max_wavelength: float, min_wavelength: float, hurst: float) -> tuple[np.ndarray, np.ndarray]:
    """Wavelengths (halving from ``max_wavelength`` down to ``min_wavelength``) and amplitudes.

    The amplitude at wavelength λ is ``amplitude·(λ/max_wavelength)^hurst``: a fractal
    (self-affine) surface with Hurst exponent ``hurst``.

    Parameters
    ----------
    amplitude : float
        Amplitude of the longest wavelength.
    max_wavelength, min_wavelength : float
        Longest and shortest wavelength kept (m).
    hurst : float
        Hurst exponent.

    Returns
    -------
    wavelengths, amplitudes : ndarray float64
        One value per octave, longest first; both empty when ``min_wavelength > max_wavelength``.
    """
    if min_wavelength > max_wavelength:
        return np.zeros(0), np.zeros(0)
    n = int(np.floor(np.log2(max_wavelength / min_wavelength))) + 1
    wl = max_wavelength / 2.0 ** np.arange(n)
    amp = amplitude * (wl / max_wavelength) ** hurst
    return wl.astype(np.float64), amp.astype(np.float64)


def fbm_grid(xs: np.ndarray, ys: np.ndarray, seed: int, wavelengths: np.ndarray, amplitudes: np.ndarray) -> np.ndarray:
    """Sum of value-noise octaves on the grid ``ys × xs`` (rows × columns), float64.

    Complexity O(len(xs)·len(ys)·octaves), parallel over rows.

    Parameters
    ----------
    xs, ys : ndarray
        Column and row coordinates (m).
    seed : int
        Noise seed; each octave adds its own offset.
    wavelengths, amplitudes : ndarray
        The octaves, as from :func:`octaves`.

    Returns
    -------
    ndarray (len(ys), len(xs)) float64
        Zeros when there are no octaves.
    """
    out = np.zeros((len(ys), len(xs)), dtype=np.float64)
    if len(wavelengths):
        _fbm_grid(np.ascontiguousarray(xs, np.float64), np.ascontiguousarray(ys, np.float64), np.int64(seed),
                  np.asarray(wavelengths, np.float64), np.asarray(amplitudes, np.float64), out)
    return out


def fbm_points(xs: np.ndarray, ys: np.ndarray, seed: int, wavelengths: np.ndarray, amplitudes: np.ndarray) -> np.ndarray:
    """Same noise as :func:`fbm_grid` at scattered points.

    Parameters
    ----------
    xs, ys : ndarray
        Coordinates of the points (m); flattened.
    seed : int
        Noise seed.
    wavelengths, amplitudes : ndarray
        The octaves, as from :func:`octaves`.

    Returns
    -------
    ndarray (N,) float64
        Noise value per point.
    """
    xs = np.ascontiguousarray(np.ravel(xs), np.float64)
    ys = np.ascontiguousarray(np.ravel(ys), np.float64)
    out = np.zeros(xs.size, dtype=np.float64)
    if len(wavelengths):
        _fbm_points(xs, ys, np.int64(seed), np.asarray(wavelengths, np.float64), np.asarray(amplitudes, np.float64), out)
    return out


def hash01(*keys: np.ndarray, seed: int) -> np.ndarray:
    """Vectorised uniform [0, 1) hash of integer keys (plot ids, tree ids); deterministic."""
    h = np.full(np.broadcast(*keys).shape, (int(seed) * 0x9E3779B97F4A7C15) & 0xFFFFFFFFFFFFFFFF, dtype=np.uint64)
    with np.errstate(over="ignore"):
        return _mix(h, keys)


def _mix(h: np.ndarray, keys) -> np.ndarray:
    for k in keys:
        h ^= np.asarray(k).astype(np.int64).astype(np.uint64) + np.uint64(0x9E3779B97F4A7C15) + (h << np.uint64(6)) + (h >> np.uint64(2))
        h ^= h >> np.uint64(33)
        h *= np.uint64(0xFF51AFD7ED558CCD)
        h ^= h >> np.uint64(33)
        h *= np.uint64(0xC4CEB9FE1A85EC53)
        h ^= h >> np.uint64(33)
    return (h >> np.uint64(11)).astype(np.float64) / float(1 << 53)
