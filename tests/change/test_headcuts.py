"""Headcut retreat on constructed DEM pairs: a head retreated by a known distance, smoothed by a known window.

The DEM is a hillslope falling to the east with a V channel running east from its head.
The head is a step (headwall) or a linear wedge; each epoch is box-smoothed by w (the
dense-matching window) and gets white noise. The lip estimator must recover the retreat
for both shapes and any window; the half-height estimator only for steps.
"""

import numpy as np
import pandas as pd
import pytest
from change.change_synth import grid, noise, xy
from scipy import ndimage

from kitegully import InputError
from kitegully.change.headcuts import COLUMNS, locate_head, measure_headcut_retreat
from kitegully.change.params import ChangeParams

DEPTH, WIDTH, Y_AXIS = 1.0, 1.5, 20.0


def _channel(g, head_x, ramp_m=0.2, depth=DEPTH):
    """Hillslope z = 100 − 0.08 x; V channel (WIDTH wide, ``depth`` deep) from head_x east, depth ramping up over ramp_m.

    A ramp of one cell (0.2 m) is a step whose position the cell-centre sampling keeps to
    sub-cell precision (the depth of the cell it falls in is interpolated linearly).
    """
    X, Y = xy(g)
    x, y = X - g.x0, g.y0 - Y
    across = np.clip(1.0 - np.abs(y - Y_AXIS) / (WIDTH / 2), 0, None)
    along = np.clip((x - head_x) / ramp_m, 0, 1)
    return 100.0 - 0.08 * x - depth * across * along


def _pair(g, retreat, window_cells, ramp1=0.2, ramp2=None, sd=0.02, shrubs=False):
    z1 = _channel(g, 20.0, ramp1)
    z2 = _channel(g, 20.0 - retreat, ramp1 if ramp2 is None else ramp2, DEPTH + 0.05)
    if shrubs:  # 1 m tall, 1.2 m wide crowns on both banks next to the head: not ground
        X, Y = xy(g)
        x, y = X - g.x0, g.y0 - Y
        for cx, cy in ((16.0, 21.8), (19.0, 18.2), (22.0, 21.9), (13.5, 18.0)):
            crown = (np.abs(x - cx) < 0.6) & (np.abs(y - cy) < 0.6)
            z1, z2 = z1 + 1.0 * crown, z2 + 1.0 * crown
    if window_cells > 1:
        z1, z2 = ndimage.uniform_filter(z1, window_cells), ndimage.uniform_filter(z2, window_cells)
    return (z1 + noise(g, sd, "h1")).astype(np.float32), (z2 + noise(g, sd, "h2")).astype(np.float32)


HEADS = pd.DataFrame(dict(head_id=[1], x=[500000.0 + 21.5], y=[4100000.0 - 21.2]))  # digitised ~2 m off
PARAMS = ChangeParams(headcut_search_radius_m=8.0, headcut_window_m=1.0)


@pytest.mark.parametrize("window_cells", [1, 5, 9])
@pytest.mark.parametrize("retreat", [0.0, 1.0, 2.5])
def test_step_retreat_does_not_depend_on_window(retreat, window_cells):
    """A headwall retreated by r, both epochs smoothed by a box of 0.2 / 1.0 / 1.8 m: lip and half height give r."""
    g = grid(200, cell=0.2)
    z1, z2 = _pair(g, retreat, window_cells)
    params = ChangeParams(headcut_search_radius_m=8.0, headcut_window_m=max(0.4, 0.2 * window_cells))  # the DEM's resolution
    out = measure_headcut_retreat(z1, z2, g, HEADS, params)
    assert list(out.columns) == COLUMNS
    assert out["retreat_m"].iloc[0] == pytest.approx(retreat, abs=0.15)
    assert out["retreat_mid_m"].iloc[0] == pytest.approx(retreat, abs=0.15)
    # the lip lies on the head: at it for a sharp DEM, w/2 upslope for a smoothed step (same at both epochs)
    assert out["x1"].iloc[0] - g.x0 == pytest.approx(20.1 - (0.1 * window_cells if window_cells > 1 else 0.1), abs=0.25)
    assert out["incision1_m"].iloc[0] > 0.2


@pytest.mark.parametrize("retreat", [2.0, 3.0])
def test_wedge_retreat_measured_at_the_lip(retreat):
    """The twin's shapes: epoch 1 ramps to full depth over 1 m, epoch 2 was cut back as a wedge of length r.

    1 m window: the lip finds r; the half-height points only (r + 1)/2 (they sit mid-ramp).
    """
    g = grid(200, cell=0.2)
    z1, z2 = _pair(g, retreat, 5, ramp1=1.0, ramp2=retreat)
    out = measure_headcut_retreat(z1, z2, g, HEADS, PARAMS)
    assert out["retreat_m"].iloc[0] == pytest.approx(retreat, abs=0.2)
    assert out["retreat_mid_m"].iloc[0] == pytest.approx((retreat + 1.0) / 2, abs=0.2)


def test_shrubs_beside_the_head_are_not_channel_banks():
    """Shrub crowns on the banks raise the DSM by 1 m; the ground surface (grey opening) ignores them."""
    g = grid(200, cell=0.2)
    z1, z2 = _pair(g, 1.5, 5, shrubs=True)
    out = measure_headcut_retreat(z1, z2, g, HEADS, PARAMS)
    assert out["retreat_m"].iloc[0] == pytest.approx(1.5, abs=0.2)


def test_no_channel_gives_nan():
    g = grid(100, cell=0.2)
    X, _ = xy(g)
    z = (100.0 - 0.08 * (X - g.x0) + noise(g, 0.02, "flat")).astype(np.float32)
    out = measure_headcut_retreat(z, z, g, pd.DataFrame(dict(head_id=[7], x=[g.x0 + 10.0], y=[g.y0 - 10.0])), PARAMS)
    assert out["head_id"].iloc[0] == 7 and np.isnan(out["retreat_m"].iloc[0])


def test_locate_head_on_a_profile():
    """Sub-station precision: a ramp from 0 to 1 m depth between s = −2.03 and −0.03 m, stations every 0.1 m."""
    s = np.arange(-8.0, 2.5 + 1e-9, 0.1)
    d = np.clip((s + 2.03) / 2.0, 0, 1)
    h = locate_head(s, d, PARAMS)
    assert h["lip"] == pytest.approx(-2.03, abs=0.02)
    assert h["mid"] == pytest.approx(-1.03, abs=0.02)
    assert h["bottom"] == pytest.approx(1.0) and h["top"] == pytest.approx(0.0)


def test_bad_profile_step():
    with pytest.raises(InputError, match=r"change.headcuts: .*profile_step_m"):
        ChangeParams(headcut_profile_step_m=0.8, headcut_window_m=1.0)
