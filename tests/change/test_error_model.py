"""The DoD's error model: σ grows where the terrain is steep or curved, never below the checkpoints' σ."""

import numpy as np
import pytest

from kitegully.change.error_model import fit_error_model, terrain_predictors


def _hill(n=400, cell=0.2):
    y, x = np.mgrid[0:n, 0:n] * cell
    # a plain on the left, a 30° wall band in the middle, a plain on the right
    z = np.clip((x - 30.0) * np.tan(np.radians(30.0)), 0.0, 10.0 * np.tan(np.radians(30.0)))
    return z + 0.001 * y + np.random.default_rng(7).normal(0.0, 0.002, z.shape), cell


def test_predictors_read_slope_in_degrees_and_curvature_at_the_edges():
    z, cell = _hill()
    slope, curv = terrain_predictors(z, cell, 1.0)
    assert np.median(slope[:, 50:100]) < 1.0
    assert np.median(slope[:, 170:190]) == pytest.approx(30.0, abs=0.5)
    assert curv[:, 150].mean() > 10 * curv[:, 75].mean()  # the wall's foot is curved, the plain is not


def test_noise_that_grows_on_the_wall_gives_a_factor_there_and_one_on_the_plain():
    z, cell = _hill()
    slope, curv = terrain_predictors(z, cell, 1.0)
    rng = np.random.default_rng(0)
    sd = np.where(slope > 15, 0.15, 0.05)
    dod = rng.normal(0.0, sd)
    unchanged = np.ones_like(z, bool)
    model = fit_error_model(dod, slope, curv, unchanged, bins=10, min_cells=200)
    f = model.factor(slope, curv)
    plain, wall = slope < 1, (slope > 29) & (slope < 31)
    assert np.median(f[plain]) == pytest.approx(1.0, abs=0.05)  # the floor: never below the checkpoints' sigma
    assert np.median(f[wall]) > 2.0
    assert model.reference_nmad == pytest.approx(np.median([0.05]), rel=0.5)
    t = model.table()
    assert len(t) <= 100 and (t["factor"] >= 1).all() and t["cells"].sum() == z.size


def test_changed_cells_outside_the_unchanged_mask_do_not_enter_the_model():
    z, cell = _hill()
    slope, curv = terrain_predictors(z, cell, 1.0)
    rng = np.random.default_rng(1)
    dod = rng.normal(0.0, 0.05, z.shape)
    wall = slope > 15
    dod[wall] -= 1.0  # the wall eroded by a metre: real change, not noise
    model = fit_error_model(dod, slope, curv, ~wall, bins=10, min_cells=200)
    assert np.median(model.factor(slope, curv)[wall]) < 1.5


def test_too_few_unchanged_cells_give_no_model():
    z, cell = _hill(60)
    slope, curv = terrain_predictors(z, cell, 1.0)
    assert fit_error_model(np.zeros_like(z), slope, curv, np.ones_like(z, bool), bins=10, min_cells=100) is None
