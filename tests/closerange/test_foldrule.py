"""The folding rule's legs measured in an orthophoto + DEM (issue 20, 001 scale check)."""

from __future__ import annotations

import numpy as np

from kitegully.closerange.foldrule import measure_folding_rule
from kitegully.io.raster import GridSpec

from .rule_drawing import rule_cells


def _scene(slope_deg=30.0, phi=0.4):
    """3 m square at 1 cm, grass-green, on a plane sloping along y; a 2 cm wide yellow L of two 1 m legs (3-D)."""
    cell = 0.01
    n = 300
    grid = GridSpec(0.0, 3.0, cell, n, n, "EPSG:32632")
    xs, ys = grid.cell_centres()
    X, Y = np.meshgrid(xs, ys)
    g = np.tan(np.radians(slope_deg))
    dem = (g * Y).astype(np.float32)
    ortho = np.zeros((3, n, n), np.uint8)
    ortho[:] = np.array([60, 110, 40], np.uint8)[:, None, None]
    corner = np.array([1.0, 1.0])
    normal = np.array([0, -g, 1.0]) / np.sqrt(1 + g * g)
    t1 = np.array([np.cos(phi), np.sin(phi), g * np.sin(phi)])
    t1 /= np.linalg.norm(t1)
    t2 = np.cross(normal, t1)
    for on, mark in rule_cells(X, Y, corner, (t1, t2)):
        ortho[:, on] = np.array([237, 204, 51], np.uint8)[:, None]
        ortho[:, mark] = 20
    return ortho, dem, grid


def test_legs_are_measured_to_two_percent_on_a_slope():
    ortho, dem, grid = _scene()
    r = measure_folding_rule(ortho, dem, grid, np.random.default_rng(0))
    assert r is not None
    assert abs(r["leg_a_m"] - 1.0) < 0.02 and abs(r["leg_b_m"] - 1.0) < 0.02
    assert r["scale_error_pct"] < 2.0
    assert abs(r["angle_deg"] - 90) < 25  # orthogonal in 3-D, less so in plan on a 30° slope


def test_no_rule_gives_none():
    ortho, dem, grid = _scene()
    ortho[:] = np.array([60, 110, 40], np.uint8)[:, None, None]
    assert measure_folding_rule(ortho, dem, grid, np.random.default_rng(0)) is None


def test_two_streaks_at_a_shallow_angle_are_not_the_rule():
    ortho, dem, grid = _scene(slope_deg=0.0)
    r = measure_folding_rule(ortho, dem, grid, np.random.default_rng(0), max_plan_angle_deg=95.0)
    assert r is None


def test_paint_fraction_unmixes_a_half_covered_cell():
    from kitegully.closerange.foldrule import paint_fraction

    grass, paint = np.array([0.24, 0.43, 0.16]), np.array([0.93, 0.80, 0.20])
    enc = lambda lin: np.rint(255 * lin ** (1 / 2.2)).astype(np.uint8)  # noqa: E731
    lin_g, lin_p = grass ** 2.2, paint ** 2.2
    ortho = np.zeros((3, 21, 21), np.uint8)
    ortho[:] = enc(lin_g)[:, None, None]
    ortho[:, 10, 5:15] = enc(0.5 * lin_g + 0.5 * lin_p)[:, None]  # a strip straddling two cell rows
    ortho[:, 11, 5:15] = enc(0.5 * lin_g + 0.5 * lin_p)[:, None]
    f = paint_fraction(ortho, tuple(paint))
    assert np.allclose(f[10:12, 5:15], 0.5, atol=0.03)
    assert np.abs(f[:8]).max() < 0.01


def test_brighter_grass_is_not_paint():
    from kitegully.closerange.foldrule import paint_fraction

    ortho = np.zeros((3, 21, 21), np.uint8)
    ortho[:] = np.array([70, 110, 45], np.uint8)[:, None, None]
    ortho[:, 10, 5:15] = np.array([95, 148, 61], np.uint8)[:, None]  # a sunlit blade: the same colour, brighter
    f = paint_fraction(ortho, (0.93, 0.80, 0.20))
    assert np.abs(f[10, 5:15]).max() < 0.05
