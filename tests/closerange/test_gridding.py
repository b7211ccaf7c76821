"""Trimmed-mean gridding on constructed point sets (issue 20)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import trim_mean

from kitegully import InputError
from kitegully.closerange.gridding import grid_points, periphery_mask, trimmed_cell_means
from kitegully.io.raster import GridSpec

GRID = GridSpec(100.0, 200.0, 0.02, 4, 3, "EPSG:32632")


def _at(row: int, col: int, n: int) -> np.ndarray:
    x = GRID.x0 + (col + 0.5) * GRID.cell + np.linspace(-0.009, 0.009, n)
    y = GRID.y0 - (row + 0.5) * GRID.cell + np.linspace(0.009, -0.009, n)
    return np.column_stack([x, y])


def test_outliers_are_trimmed_exactly_25_percent_per_tail():
    cells = {
        (0, 0): [1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 100.0, -50.0],  # n=8, k=2: -50, 1 | 1, 100 dropped -> 1
        (0, 1): [0.0, 1.0, 2.0, 100.0],  # n=4, k=1: keeps 1, 2 -> 1.5
        (1, 2): [0.0, 0.0, 9.0],  # n=3, k=0: plain mean 3
        (2, 3): [5.0],  # n=1
        (2, 0): [10.0, 0.0, 20.0, 30.0, 40.0, -1000.0, 1000.0],  # n=7, k=1 -> mean(0,10,20,30,40)=20
    }
    pts, cols = [], []
    for (r, c), zs in cells.items():
        xy = _at(r, c, len(zs))
        pts.append(np.column_stack([xy, zs]))
        cols.append(np.column_stack([np.array(zs) % 256, np.zeros(len(zs)), np.full(len(zs), 7)]))
    P = np.vstack(pts)
    rng = np.random.default_rng(0)
    order = rng.permutation(len(P))  # input order must not matter
    out = grid_points(P[order], GRID, colours=np.vstack(cols)[order].astype(np.uint8))
    assert out.dem[0, 0] == pytest.approx(1.0)
    assert out.dem[0, 1] == pytest.approx(1.5)
    assert out.dem[1, 2] == pytest.approx(3.0)
    assert out.dem[2, 3] == pytest.approx(5.0)
    assert out.dem[2, 0] == pytest.approx(20.0)
    assert np.isnan(out.dem[1, 1])
    assert out.count[0, 0] == 8 and out.count[1, 1] == 0
    # colours are the mean over the same kept points: cell (0, 1) keeps z = 1, 2 -> red 1.5 -> 2
    assert out.ortho[0, 0, 1] == 2 and out.ortho[2, 0, 1] == 7 and out.ortho[2, 1, 1] == 0


def test_matches_scipy_trim_mean_on_random_cells():
    rng = np.random.default_rng(3)
    idx = rng.integers(0, 50, 5000)
    z = rng.standard_normal(5000) + rng.choice([0, 30], 5000, p=[0.9, 0.1])
    mean, count, _ = trimmed_cell_means(idx, z, 60, 0.25)
    for c in range(60):
        if count[c]:
            assert mean[c] == pytest.approx(trim_mean(z[idx == c], 0.25))
        else:
            assert np.isnan(mean[c])


def test_trim_must_leave_points():
    with pytest.raises(InputError, match=r"trim: 0.5 is not in \[0, 0.5\)"):
        trimmed_cell_means(np.zeros(3, int), np.zeros(3), 1, 0.5)


def test_periphery_is_cropped_by_the_camera_ring():
    grid = GridSpec(0.0, 10.0, 0.5, 20, 20, "EPSG:32632")  # 10 m square
    ang = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    cams = np.column_stack([5 + 3 * np.cos(ang), 5 + 3 * np.sin(ang)])
    for shape in ("hull", "circle"):
        m = periphery_mask(grid, cams, shape)
        xs, ys = grid.cell_centres()
        X, Y = np.meshgrid(xs, ys)
        r = np.hypot(X - 5, Y - 5)
        assert m[r < 2.9].all() and not m[r > 3.05].any()
    flat = np.column_stack([np.repeat(xs, 20), np.tile(ys, 20), np.ones(400)])
    out = grid_points(flat, grid, camera_xy=cams)
    assert np.isnan(out.dem[0, 0]) and out.dem[10, 10] == 1.0
    with pytest.raises(InputError, match="at least 3 are needed"):
        periphery_mask(grid, cams[:2])
