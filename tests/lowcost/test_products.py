"""The survey's rasters: white-balanced reflectance and the tie points' TIN DSM."""

from __future__ import annotations

import numpy as np

from kitegully.lowcost.products import tin_dsm, white_balance


def test_white_balance_returns_the_panel_reflectance_on_the_panel():
    gamma = 2.2
    panel_dn = np.array([240.0, 200.0, 180.0])
    img = np.stack([np.full((2, 2), v, np.uint8) for v in np.rint(panel_dn)])
    img[:, 0, 0] = 0
    out = white_balance(img, panel_dn, 0.99, gamma)
    assert np.isnan(out[:, 0, 0]).all()
    np.testing.assert_allclose(out[:, 1, 1], 0.99, rtol=1e-6)
    half = white_balance(np.rint(panel_dn * 0.5 ** (1 / gamma)).astype(np.uint8)[:, None, None], panel_dn, 1.0, gamma)
    np.testing.assert_allclose(half.ravel(), 0.5, rtol=0.02)                 # linear after the tone curve


def test_tin_dsm_reproduces_a_plane():
    rng = np.random.default_rng(0)
    xy = rng.uniform(0, 10, (400, 2)) + [290000.0, 6115000.0]
    z = 0.1 * (xy[:, 0] - 290000.0) - 0.05 * (xy[:, 1] - 6115000.0) + 2.0
    dsm, grid = tin_dsm(np.column_stack([xy, z]), 0.5, "EPSG:32756")
    assert dsm.shape == grid.shape
    xs, ys = np.meshgrid(*grid.cell_centres())
    ok = np.isfinite(dsm)
    assert ok.mean() > 0.8
    np.testing.assert_allclose(dsm[ok], (0.1 * (xs - 290000.0) - 0.05 * (ys - 6115000.0) + 2.0)[ok], atol=1e-4)
