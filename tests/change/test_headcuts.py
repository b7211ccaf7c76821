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
from kitegully.change.headcuts import COLUMNS, fit_head, locate_head, measure_headcut_retreat
from kitegully.change.params import ChangeParams
from kitegully.seeds import rng_for

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


def noise_1d(n, sd, seed=3):
    return sd * rng_for(seed, "test", "fit_head").standard_normal(n)


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
    # lip: within 0.3 m (a ramp shorter than the window is a step to the fit, so where it
    # begins is known to about a quarter window at each epoch); half height: 0.15 m
    assert out["retreat_m"].iloc[0] == pytest.approx(retreat, abs=0.3)
    assert out["retreat_mid_m"].iloc[0] == pytest.approx(retreat, abs=0.15)
    # the fitted (smoothed) head model puts the lip on the headwall for any window (the former
    # extrapolated 25-75 % line put it w/2 upslope)
    assert out["x1"].iloc[0] - g.x0 == pytest.approx(20.0, abs=0.3)
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
    """A ramp from 0 to 1 m depth between s = −2.03 and −0.03 m, stations every 0.1 m: lip to a station, mid sub-station."""
    s = np.arange(-8.0, 2.5 + 1e-9, 0.1)
    d = np.clip((s + 2.03) / 2.0, 0, 1)
    h = locate_head(s, d, PARAMS)
    assert h["lip"] == pytest.approx(-2.03, abs=0.06)
    assert h["mid"] == pytest.approx(-1.03, abs=0.02)
    assert h["bottom"] == pytest.approx(1.0, abs=0.05) and h["top"] == pytest.approx(0.0, abs=0.05)


@pytest.mark.parametrize("lip, length", [(-1.0, 0.0), (-2.5, 2.5), (-3.4, 0.2)])
def test_fit_head_recovers_a_smoothed_ramp_or_step(lip, length):
    """A step or wedge smoothed by the 1 m window with noise: the fitted lip is where the incision begins."""
    s = np.arange(-10.0, 2.5 + 1e-9, 0.1)
    f = np.clip((s - lip) / length, 0, 1) if length > 0 else (s >= lip).astype(float)
    d = 0.05 + 0.8 * ndimage.uniform_filter1d(f, 10, mode="nearest") + noise_1d(s.size, 0.03)
    h = fit_head(s, d, PARAMS)
    assert h["lip"] == pytest.approx(lip, abs=0.15)
    assert h["length"] == pytest.approx(length, abs=0.4)
    assert h["bottom"] - h["top"] == pytest.approx(0.8, abs=0.08)


def test_fit_head_ignores_hollows_beyond_a_season_of_retreat():
    """A 0.6 m hollow 7 m upslope of the head (farther than max_retreat_m + window_m): the lip stays on the head."""
    s = np.arange(-10.0, 2.5 + 1e-9, 0.1)
    d = 0.7 * ndimage.uniform_filter1d((s >= -0.5).astype(float), 10, mode="nearest")
    d = d + 0.6 * np.exp(-0.5 * ((s + 7.5) / 0.6) ** 2)
    assert fit_head(s, d, PARAMS)["lip"] == pytest.approx(-0.5, abs=0.15)


def test_step_then_wedge_is_not_biased_by_half_a_window():
    """Epoch 1 a headwall, epoch 2 cut back as a wedge of r = 2 m (the twin's shapes), 1 m window.

    The former lip (extrapolated 25-75 % line) put the step's lip w/2 upslope but the wedge's
    at its tip, so it measured r − w/2; the fitted model measures r.
    """
    g = grid(200, cell=0.2)
    z1, z2 = _pair(g, 2.0, 5, ramp1=0.2, ramp2=2.0)
    out = measure_headcut_retreat(z1, z2, g, HEADS, PARAMS)
    assert out["retreat_m"].iloc[0] == pytest.approx(2.0, abs=0.25)


def test_bad_profile_step():
    with pytest.raises(InputError, match=r"change.headcuts: .*profile_step_m"):
        ChangeParams(headcut_profile_step_m=0.8, headcut_window_m=1.0)


def test_a_lip_in_a_void_is_not_a_measurement():
    """The profile's stations within a window of the head are void (no DSM there): no lip, no retreat."""
    s = np.arange(-10.0, 2.5 + 1e-9, 0.1)
    d = 0.7 * ndimage.uniform_filter1d((s >= -0.5).astype(float), 10, mode="nearest")
    assert np.isfinite(locate_head(s, d, PARAMS)["lip"])
    d[(s > -1.2) & (s < -0.2)] = np.nan
    assert np.isnan(locate_head(s, d, PARAMS)["lip"])


@pytest.mark.parametrize("retreat", [1.0, 2.5])
@pytest.mark.parametrize("crown_m", [1.2, 2.0])
def test_shrub_on_the_stretch_the_head_cut_through(retreat, crown_m):
    """The twin's case: at epoch 1 a 1 m shrub stands on the stretch upslope of the headwall; at
    epoch 2 the head has cut through it as a wedge of length r and the shrub is gone. Both
    epochs smoothed by the 1 m window, 2 cm noise. (The former 25-75 % chord gave 1.93 and
    1.78 m for r = 2.5 m: the step's lip w/2 upslope, the wedge's at its tip.)"""
    g = grid(200, cell=0.2)
    X, Y = xy(g)
    x, y = X - g.x0, g.y0 - Y
    crown = (np.abs(x - (20.0 - retreat / 2 - 0.3)) < max(retreat / 2, 0.6)) & (np.abs(y - Y_AXIS) < crown_m / 2)
    z1 = ndimage.uniform_filter(_channel(g, 20.0, 0.2) + 1.0 * crown, 5) + noise(g, 0.02, "shrub1")
    z2 = ndimage.uniform_filter(_channel(g, 20.0 - retreat, retreat, DEPTH + 0.05), 5) + noise(g, 0.02, "shrub2")
    out = measure_headcut_retreat(z1.astype(np.float32), z2.astype(np.float32), g, HEADS, PARAMS)
    assert out["retreat_m"].iloc[0] == pytest.approx(retreat, abs=0.25)
