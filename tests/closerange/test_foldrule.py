"""The folding rule's legs measured in an orthophoto + DEM (issue 20, 001 scale check)."""

from __future__ import annotations

import numpy as np

from kitegully.closerange.foldrule import measure_folding_rule
from kitegully.io.raster import GridSpec


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
    for t in (t1, t2):
        e = t[:2] / np.linalg.norm(t[:2])
        plan = np.linalg.norm(t[:2])
        along = (X - corner[0]) * e[0] + (Y - corner[1]) * e[1]
        across = -(X - corner[0]) * e[1] + (Y - corner[1]) * e[0]
        on = (along >= -0.01) & (along <= plan) & (np.abs(across) <= 0.01)
        leg = along / plan
        ortho[:, on] = np.array([237, 204, 51], np.uint8)[:, None]
        ortho[:, on & (np.abs(leg - np.round(leg, 1)) <= 0.005)] = 20
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
