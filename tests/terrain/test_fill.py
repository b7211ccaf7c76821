"""The priority flood with slope tracing (issue 21) equals the plain improved priority
flood (Barnes et al. 2014) bit for bit, raised-cell count included."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.ndimage as ndi
from numba import njit

from kitegully.terrain.fill import _DC, _DR, _fifo_push, _heap_pop, _heap_push, priority_flood_fill


@njit(cache=False)
def _plain_priority_flood(w, valid, eps, dr, dc):
    """Every slope cell through the heap, raised cells through a FIFO (the former kernel)."""
    h, wd = w.shape
    flat = w.ravel()
    vflat = valid.ravel()
    closed = np.zeros(h * wd, dtype=np.uint8)
    hidx = np.empty(1024, dtype=np.int64)
    hkey = np.empty(1024, dtype=np.float64)
    nheap = 0
    pit = np.empty(16, dtype=np.int64)
    phead = 0
    psize = 0
    nraised = 0
    for r in range(h):
        for c in range(wd):
            i = r * wd + c
            if not vflat[i]:
                closed[i] = 1
                continue
            seed = r == 0 or c == 0 or r == h - 1 or c == wd - 1
            if not seed:
                for k in range(8):
                    if not vflat[(r + dr[k]) * wd + c + dc[k]]:
                        seed = True
                        break
            if seed:
                closed[i] = 1
                hidx, hkey, nheap = _heap_push(hidx, hkey, nheap, i, flat[i])
    while nheap > 0 or psize > 0:
        if psize > 0 and (nheap == 0 or flat[pit[phead]] <= hkey[0]):
            i = pit[phead]
            phead = (phead + 1) % pit.size
            psize -= 1
        else:
            i, nheap = _heap_pop(hidx, hkey, nheap)
        r = i // wd
        c = i - r * wd
        zc = flat[i]
        for k in range(8):
            rr = r + dr[k]
            cc = c + dc[k]
            if rr < 0 or cc < 0 or rr >= h or cc >= wd:
                continue
            j = rr * wd + cc
            if closed[j]:
                continue
            closed[j] = 1
            target = zc + eps
            if flat[j] <= target:
                if flat[j] < target:
                    nraised += 1
                flat[j] = target
                pit, phead, psize = _fifo_push(pit, phead, psize, j)
            else:
                hidx, hkey, nheap = _heap_push(hidx, hkey, nheap, j, flat[j])
    return nraised


def _dem(seed: int, shape=(300, 340)) -> np.ndarray:
    """Slopes (traced at once), rough noise and pits (through the heap), flats, nodata."""
    rng = np.random.default_rng(seed)
    h, w = shape
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    z = 0.04 * y + 0.01 * x + 2 * np.sin(x / 40) * np.cos(y / 55)
    z += ndi.gaussian_filter(rng.standard_normal(shape), 2.0) * 0.2 * (seed % 3)
    pr, pc = rng.integers(2, h - 2, 300), rng.integers(2, w - 2, 300)
    z[pr, pc] -= rng.uniform(0.3, 2.0, 300)
    z[100:140, 200:260] = np.round(z[100:140, 200:260])  # flats and terraces
    if seed % 2:
        z[:30, :50] = np.nan  # outside area
        z[150:160, 60:75] = np.nan  # interior nodata (an outlet)
    return z


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("eps", [0.0, 1e-4])
def test_traced_fill_equals_plain_priority_flood(seed, eps):
    z = _dem(seed)
    filled, n = priority_flood_fill(z, eps)
    ref = np.array(z, dtype=np.float64, copy=True)
    n_ref = _plain_priority_flood(ref, np.isfinite(ref), eps, _DR, _DC)
    assert n_ref > 100  # the DEM has depressions to fill
    assert n == n_ref
    assert np.array_equal(filled, ref, equal_nan=True)


def test_single_row_and_column_grids():
    for z in (np.array([[3.0, 1.0, 2.0, 0.5]]), np.array([[3.0], [1.0], [2.0]])):
        filled, n = priority_flood_fill(z, 0.0)
        assert np.array_equal(filled, z) and n == 0
