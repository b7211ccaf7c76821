"""The DoD's error model: σ grows where the terrain is steep, curved or not the ground; never below the checkpoints' σ."""

import numpy as np
import pytest

from kitegully.change.error_model import PREDICTORS, fit_error_model, heteroscedastic_sigma, terrain_predictors


def _hill(n=400, cell=0.2):
    y, x = np.mgrid[0:n, 0:n] * cell
    # a plain on the left, a 30° wall band in the middle, a plain on the right
    z = np.clip((x - 30.0) * np.tan(np.radians(30.0)), 0.0, 10.0 * np.tan(np.radians(30.0)))
    return z + 0.001 * y + np.random.default_rng(7).normal(0.0, 0.002, z.shape), cell


def _shrubs(z, cell):
    """0.8 m high clumps, 1.6 m across, every 6 m on the left plain."""
    y, x = np.mgrid[0:z.shape[0], 0:z.shape[1]] * cell
    clump = (np.hypot((x % 6.0) - 3.0, (y % 6.0) - 3.0) < 0.8) & (x < 24.0)
    return z + 0.8 * clump, clump


def _wall_and_shrubs(seed):
    """The hill with shrub clumps, its predictors, and a DoD whose noise is 0.05 m on the plain,
    0.12 m on the clumps and 0.15 m on the wall; returns (z, cell, predictors, dod, plain, wall, clump)."""
    z, cell = _hill()
    z, clump = _shrubs(z, cell)
    preds = terrain_predictors(z, cell, 1.0, 3.0)
    slope = preds[0]
    dod = np.random.default_rng(seed).normal(0.0, np.where(slope > 15, 0.15, np.where(clump, 0.12, 0.05)))
    return z, cell, preds, dod, (slope < 1) & ~clump, (slope > 29) & (slope < 31), clump


def test_predictors_read_slope_curvature_and_what_stands_on_the_ground():
    z, cell = _hill()
    z, clump = _shrubs(z, cell)
    slope, curv, height = terrain_predictors(z, cell, 1.0, 3.0)
    assert np.median(slope[:, 125:140]) < 1.0  # the open plain between the clumps' rows and the wall
    assert np.median(slope[:, 170:190]) == pytest.approx(30.0, abs=0.5)
    assert curv[:, 150].mean() > 10 * curv[:, 130].mean()  # the wall's foot is curved, the plain is not
    assert np.median(height[clump]) > 0.5 and np.median(height[:, 125:140]) < 0.02
    assert len(PREDICTORS) == 3


def test_noise_that_grows_on_the_wall_and_the_crowns_gives_a_factor_there_and_one_on_the_plain():
    z, cell, preds, dod, plain, wall, clump = _wall_and_shrubs(0)
    model = fit_error_model(dod, preds, np.ones_like(z, bool), bins=6, min_cells=50)
    f = model.factor(preds)
    assert np.median(f[plain]) == pytest.approx(1.0, abs=0.05)  # the floor: never below the checkpoints' sigma
    assert np.median(f[wall]) > 2.0
    assert np.median(f[clump]) > 1.6
    t = model.table()
    assert (t["factor"] >= 1).all() and t["cells"].sum() == z.size and "height_above_ground_m_min" in t


def test_changed_cells_outside_the_unchanged_mask_do_not_enter_the_model():
    z, cell = _hill()
    preds = terrain_predictors(z, cell, 1.0, 3.0)
    rng = np.random.default_rng(1)
    dod = rng.normal(0.0, 0.05, z.shape)
    wall = preds[0] > 15
    dod[wall] -= 1.0  # the wall eroded by a metre: real change, not noise
    model = fit_error_model(dod, preds, ~wall, bins=6, min_cells=50)
    assert np.median(model.factor(preds)[wall]) < 1.5


def test_too_few_unchanged_cells_give_a_uniform_sigma_and_say_so():
    z, cell = _hill(60)
    preds = terrain_predictors(z, cell, 1.0, 3.0)
    assert fit_error_model(np.zeros_like(z), preds, np.ones_like(z, bool), bins=10, min_cells=100) is None
    sigma = np.full(z.shape, 0.07, np.float32)
    out, row = heteroscedastic_sigma(sigma, z, np.zeros_like(z), np.ones_like(z, bool), cell, 1.0, 3.0)
    assert np.array_equal(out, sigma) and "uniform" in row["source"]


def test_the_factor_is_relative_to_the_checkpoints_terrain():
    """sigma states the DEMs' error at the checkpoints (open plain): a wall 3 x noisier gets 3 x sigma."""
    z, cell, preds, dod, plain, wall, _ = _wall_and_shrubs(4)
    sigma = np.full(z.shape, 0.05, np.float32)
    unchanged = np.ones_like(z, bool)
    r, c = np.nonzero(plain)
    cps = (r[::400], c[::400])
    with_cp, row = heteroscedastic_sigma(sigma, z, dod, unchanged, cell, 1.0, 3.0, reference_cells=cps)
    overall, _ = heteroscedastic_sigma(sigma, z, dod, unchanged, cell, 1.0, 3.0)
    assert np.median(with_cp[wall]) == pytest.approx(0.15, rel=0.15)
    assert np.median(overall[wall]) < np.median(with_cp[wall])  # the shrubs' noise lifts the all-cells NMAD
    assert np.median(with_cp[plain]) == pytest.approx(0.05, rel=0.05)  # never below the stated sigma
    assert row["epoch"] == "DoD factor"
