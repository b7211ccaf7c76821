"""Terrain library: FFT smoothing, hole interpolation, priority-flood filling, D8 tracing."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.ndimage as ndi

from kitegully.terrain import (
    d8_directions,
    gaussian_kernel_1d,
    gaussian_smooth_fft,
    interior_holes,
    interpolate_holes,
    priority_flood_fill,
    trace_paths,
)
from kitegully.terrain.flow import D8_OFFSETS, END_OUTLET


# ---------------------------------------------------------------- references
def reference_fill(z: np.ndarray, eps: float) -> np.ndarray:
    """Planchon-Darboux style fixed point W = max(Z, min_nb W + eps), outlets fixed at Z.

    Deliberately simple (iterated vectorised relaxation), independent of the heap code.
    """
    valid = np.isfinite(z)
    h, w = z.shape
    pad_valid = np.pad(valid, 1, constant_values=False)
    outlet = np.zeros_like(valid)
    for dr, dc in D8_OFFSETS:
        outlet |= ~pad_valid[1 + dr : 1 + dr + h, 1 + dc : 1 + dc + w]
    outlet &= valid
    wv = np.where(valid & ~outlet, np.inf, z)
    while True:
        p = np.pad(np.where(valid, wv, np.inf), 1, constant_values=np.inf)
        nb = np.min([p[1 + dr : 1 + dr + h, 1 + dc : 1 + dc + w] for dr, dc in D8_OFFSETS], axis=0)
        new = np.where(valid & ~outlet, np.minimum(wv, np.maximum(z, nb + eps)), wv)
        if np.array_equal(new, wv, equal_nan=True):
            return new
        wv = new


def outlet_mask(valid: np.ndarray) -> np.ndarray:
    pv = np.pad(valid, 1, constant_values=False)
    h, w = valid.shape
    m = np.zeros_like(valid)
    for dr, dc in D8_OFFSETS:
        m |= ~pv[1 + dr : 1 + dr + h, 1 + dc : 1 + dc + w]
    return m & valid


# ---------------------------------------------------------------- smoothing
def test_kernel_normalised_and_radius():
    k = gaussian_kernel_1d(2.5, truncate=4.0)
    assert k.size == 2 * 10 + 1
    assert k.sum() == pytest.approx(1.0, abs=1e-12)
    assert np.argmax(k) == 10


def test_fft_smoothing_equals_direct_normalised_convolution():
    rng = np.random.default_rng(1)
    z = rng.normal(100, 3, (70, 90))
    z[20:30, 40:55] = np.nan
    z[:, :5] = np.nan
    k = gaussian_kernel_1d(4.0)
    valid = np.isfinite(z)
    zz = np.where(valid, z, 0.0)
    num = ndi.correlate1d(ndi.correlate1d(zz, k, axis=1, mode="constant"), k, axis=0, mode="constant")
    den = ndi.correlate1d(ndi.correlate1d(valid * 1.0, k, axis=1, mode="constant"), k, axis=0, mode="constant")
    expected = num / den
    got = gaussian_smooth_fft(z, 4.0, linear_edges=False)
    # float32 output around 100 m: resolution 1e-5 m
    np.testing.assert_allclose(got, expected, atol=3e-5)


def test_fft_smoothing_matches_scipy_gaussian_filter_in_interior():
    rng = np.random.default_rng(2)
    z = rng.normal(0, 1, (120, 130)).astype(np.float32)
    got = gaussian_smooth_fft(z, 3.0, truncate=4.0)
    ref = ndi.gaussian_filter(z.astype(np.float64), 3.0, truncate=4.0, mode="constant")
    inner = (slice(13, -13), slice(13, -13))  # beyond the kernel radius the window is full
    np.testing.assert_allclose(got[inner], ref[inner], atol=1e-5)


def test_smoothing_of_a_plane_has_no_edge_or_hole_bias():
    # On a 10 % slope a plain normalised convolution is biased by g·(x̄ − x) ≈ 1 m at the
    # edge; the first-order correction must reproduce the plane to float32 resolution.
    y, x = np.mgrid[0:200, 0:260] * 0.2
    z = (50 + 0.1 * x - 0.05 * y).astype(np.float32)
    z[60:90, 100:160] = np.nan
    z[:, :20] = np.nan
    plain = gaussian_smooth_fft(z, 25, linear_edges=False)
    assert np.nanmax(np.abs(plain - z)) > 0.3
    corrected = gaussian_smooth_fft(z, 25)
    assert np.nanmax(np.abs(corrected - z)) < 1e-4
    # the hole is filled by the smoothing, the far outside is NaN-free only where weighted
    assert np.isfinite(corrected[70, 120])


def test_smoothing_rejects_all_nodata():
    with pytest.raises(ValueError, match="no valid cell"):
        gaussian_smooth_fft(np.full((10, 10), np.nan), 2.0)


# ---------------------------------------------------------------- holes
def test_holes_interpolated_exactly_on_a_plane_and_outer_nodata_kept():
    y, x = np.mgrid[0:60, 0:80].astype(float)
    z = 10 + 0.3 * x + 0.2 * y
    z_holes = z.copy()
    z_holes[20:30, 30:45] = np.nan  # interior hole
    z_holes[0:10, 0:10] = np.nan  # touches the edge: outside
    holes = interior_holes(np.isfinite(z_holes))
    assert holes.sum() == 150
    filled, n = interpolate_holes(z_holes)
    assert n == 150
    np.testing.assert_allclose(filled[20:30, 30:45], z[20:30, 30:45], atol=1e-9)
    assert np.isnan(filled[0:10, 0:10]).all()


# ---------------------------------------------------------------- filling
def test_fill_hand_made_pit_and_nested_depressions():
    z = np.array(
        [
            [9, 9, 9, 9, 9, 9, 9],
            [9, 5, 5, 8, 4, 4, 9],
            [9, 5, 1, 6, 4, 2, 9],
            [9, 5, 5, 8, 4, 4, 9],
            [9, 9, 9, 3, 9, 9, 9],
        ],
        dtype=float,
    )
    filled, n = priority_flood_fill(z, 0.0)
    # The outlet is the 3 on the bottom edge. The left pit (1) spills at 5 through the
    # diagonal [3,2] -> [4,3]; the right pit (2) spills at 4 through [3,4] -> [4,3].
    expected = z.copy()
    expected[2, 2] = 5
    expected[2, 5] = 4
    np.testing.assert_array_equal(filled, expected)
    np.testing.assert_array_equal(filled, reference_fill(z, 0.0))
    eps_filled, _ = priority_flood_fill(z, 0.01)
    assert eps_filled[2, 2] == pytest.approx(5.01) and eps_filled[2, 5] == pytest.approx(4.01)
    assert n == int(np.sum(filled > z))


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("eps", [0.0, 1e-3])
def test_fill_equals_reference_on_random_dems(seed, eps):
    rng = np.random.default_rng(seed)
    z = rng.random((25, 31)) * 10 + (seed % 3)
    if seed % 2:
        z[:4, :7] = np.nan  # outside area: its rim drains like the edge
        z[12, 14:17] = np.nan  # interior nodata also acts as an outlet
    filled, _ = priority_flood_fill(z, eps)
    ref = reference_fill(z, eps)
    np.testing.assert_allclose(filled, ref, rtol=0, atol=1e-9, equal_nan=True)
    assert np.all(filled[np.isfinite(z)] >= z[np.isfinite(z)])


@pytest.mark.parametrize("seed", range(4))
def test_epsilon_fill_makes_every_inner_cell_drain(seed):
    rng = np.random.default_rng(10 + seed)
    # smooth-ish terrain with big flats and depressions
    z = np.round(ndi.gaussian_filter(rng.random((60, 70)), 3) * 20) / 2
    filled, _ = priority_flood_fill(z, 1e-4)
    dirs = d8_directions(filled)
    inner = ~outlet_mask(np.isfinite(z))
    assert np.all(dirs[inner] != 255)
    # the rise across a flat is bounded by eps times the number of cells
    assert np.max(filled - reference_fill(z, 0.0)) <= 1e-4 * z.size


# ---------------------------------------------------------------- D8 and tracing
def test_d8_on_a_plane_points_down_slope():
    y, x = np.mgrid[0:10, 0:10].astype(float)
    z = 100 - x  # falls to the east
    d = d8_directions(z)
    assert np.all(d[:, :-1] == 4)  # code 4 = (0, +1) = E
    z2 = 100 - x - y  # falls to the south-east: diagonal drop 2/√2 > 1
    assert np.all(d8_directions(z2)[:-1, :-1] == 7)


@pytest.mark.parametrize("with_nodata", [False, True])
def test_every_traced_path_descends_to_an_outlet(with_nodata):
    rng = np.random.default_rng(5)
    z = ndi.gaussian_filter(rng.random((80, 90)), 2) * 50
    if with_nodata:
        z[30:50, 60:] = np.nan  # outside area reaching the east edge
    filled, _ = priority_flood_fill(z, 1e-4)
    valid = np.isfinite(z)
    heads = rng.choice(np.flatnonzero(valid), 40, replace=False)
    cells, down, starts, ends = trace_paths(filled, heads)
    outlets = outlet_mask(valid).ravel()
    flat = filled.ravel()
    assert np.all(ends != 2)  # no pits on an ε-filled DEM
    for p in range(heads.size):
        path = cells[starts[p] : starts[p + 1]]
        if ends[p] == 3:
            assert path.size == 0
            continue
        assert np.all(np.diff(flat[path]) < 0)  # strictly downhill
        if ends[p] == END_OUTLET:
            assert outlets[path[-1]] and down[starts[p + 1] - 1] == -1
        else:  # merged: the next cell belongs to an earlier path, which ends at an outlet
            assert down[starts[p + 1] - 1] in set(cells[: starts[p]])
    assert len(np.unique(cells)) == cells.size


def test_fill_nearest_takes_the_nearest_valid_value():
    """The one nearest-fill of the project (dense matching, orthophoto, OBIA slope)."""
    from kitegully.terrain.holes import fill_nearest

    z = np.full((5, 7), np.nan)
    z[0, 0], z[4, 6] = 1.0, 2.0
    f = fill_nearest(z)
    assert f[1, 1] == 1.0 and f[3, 5] == 2.0 and f[0, 6] in (1.0, 2.0)
    assert np.isfinite(f).all() and np.isnan(z[1, 1])  # input untouched
    # every cell takes the value of a valid cell at the smallest distance
    rr, cc = np.indices(z.shape)
    d1, d2 = np.hypot(rr - 0, cc - 0), np.hypot(rr - 4, cc - 6)
    assert np.all(f[d1 < d2] == 1.0) and np.all(f[d2 < d1] == 2.0)
    full = np.arange(6.0).reshape(2, 3)
    assert fill_nearest(full) is full
    empty = np.full((2, 2), np.nan)
    assert fill_nearest(empty) is empty
