"""Thalweg: MFD catchment area, TCI, snakes smoothing, thalweg lines on a notch."""

from __future__ import annotations

import numpy as np
import pytest

from kitegully.polygons.thalweg import mfd_catchment_area, snakes_smooth, thalweg_lines, topographic_convergence_index
from .polygon_synthetic import notch_dem


def test_mfd_conserves_area_on_a_plane():
    cell = 0.5
    r, c = np.mgrid[0:50, 0:30]
    z = 100.0 - 0.1 * r * cell + 0.0 * c  # falls to the south; no lateral flow within a row
    acc = mfd_catchment_area(z, cell)
    total = z.size * cell * cell
    assert acc[-1].sum() == pytest.approx(total, rel=1e-9)
    # a cell in the middle collects about its upslope column
    assert acc[25, 15] == pytest.approx(26 * cell * cell, rel=0.05)


def test_tci_highest_in_the_notch_and_thalweg_follows_it():
    dem, grid, xc = notch_dem("V", 8.0, 2.0, cross_slope=0.05)
    tci, sca = topographic_convergence_index(dem, grid.cell, 1.1, 0.001)
    xs, _ = grid.cell_centres()
    axis = int(np.argmin(np.abs(xs - xc)))
    assert tci[200, axis] > np.nanmax(tci[200, : axis - 20]) + 2.0
    lines, cells = thalweg_lines(tci, grid, 9.0, 10.0, 2.0, 1.0, 1.0)
    longest = max(lines, key=lambda l: l.length)
    x = np.asarray(longest.coords)[:, 0]
    assert np.abs(x - xc).max() <= 2 * grid.cell


def test_snakes_keep_ends_and_smooth_noise():
    t = np.linspace(0, 100, 101)
    rng = np.random.default_rng(1)
    xy = np.column_stack([t, 0.3 * rng.standard_normal(t.size)])
    sm = snakes_smooth(xy, 1.0, 1.0)
    assert np.allclose(sm[[0, -1]], xy[[0, -1]])
    assert np.abs(sm[5:-5, 1]).std() < 0.5 * np.abs(xy[5:-5, 1]).std()
