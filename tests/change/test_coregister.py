"""Co-registration recovers a known horizontal shift, vertical offset and tilt."""

import numpy as np
import pytest
from change.change_synth import grid, noise, terrain, xy

from kitegully.change.coregister import coregister
from kitegully.change.params import ChangeParams
from kitegully.io.raster import Raster


@pytest.mark.parametrize("shift", [(0.6, -0.4), (-0.25, 0.15)])
def test_recovers_shift_offset_and_tilt(shift):
    g = grid()
    X, Y = xy(g)
    dx, dy, dz, tx, ty = shift[0], shift[1], 0.12, 2e-3, -1e-3
    z1 = terrain(X, Y).astype(np.float32)
    # epoch 2: the same terrain displaced by +shift, raised by dz, tilted, with noise
    xc, yc = X.mean(), Y.mean()
    z2 = terrain(X - dx, Y - dy) + dz + tx * (X - xc) + ty * (Y - yc) + noise(g, 0.03, "coreg")
    params = ChangeParams(coreg_tolerance_m=0.002)
    out, info = coregister(z1, Raster(z2.astype(np.float32), g), g, np.ones(z1.shape, bool), params)
    assert info.converged
    assert info.dx_m == pytest.approx(dx, abs=0.03)
    assert info.dy_m == pytest.approx(dy, abs=0.03)
    assert info.dz_m == pytest.approx(dz, abs=0.01)
    assert info.tilt_x == pytest.approx(tx, abs=1e-4)
    assert info.tilt_y == pytest.approx(ty, abs=1e-4)
    assert info.after["nmad_m"] < 0.6 * info.before["nmad_m"]
    assert info.after["nmad_m"] <= 0.035  # only the 0.03 m noise is left (bilinear resampling smooths it)


def test_disabled_changes_nothing():
    g = grid(50)
    X, Y = xy(g)
    z1 = terrain(X, Y).astype(np.float32)
    z2 = (z1 + 0.3).astype(np.float32)
    out, info = coregister(z1, Raster(z2, g), g, np.ones(z1.shape, bool), ChangeParams(coreg_enabled=False))
    assert np.allclose(out, z2)
    assert info.dx_m == 0.0 and info.before == info.after
