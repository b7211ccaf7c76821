"""Digitised gully heads: the visibility rule on constructed gullies (twin/survey.py)."""

from __future__ import annotations

import numpy as np
import pytest

from kitegully.io.raster import GridSpec
from kitegully.twin.gullies import Gully
from kitegully.twin.landcover import CODE
from kitegully.twin.survey import digitised_heads, resolved_relief, shape_factor, visible_head_index

VIS = {"dsm_sigma_z_m": 0.05, "dsm_resolution_m": 1.0, "relief_k": 3.0, "min_run_cells": 3,
       "marginal_miss_rate": 0.0, "false_heads_per_km2": 0.0, "false_head_classes": ["track"],
       "false_head_clearance_m": 15.0}


def _gully(gid, depth, width, shape="V", x0=0.0, y0=0.0):
    n = len(depth)
    return Gully(gid, "gully", "right", shape, x0 + np.arange(n, dtype=float), np.full(n, y0),
                 depth=np.asarray(depth, float), width=np.asarray(width, float))


def test_relief_is_depth_for_wide_channels_and_area_over_window_for_narrow_ones():
    # 2 m wide V, 0.4 m deep: wider than the 1 m window, the DSM keeps the depth
    assert resolved_relief(0.4, 2.0, 0.5, 1.0) == pytest.approx(0.4)
    # 0.5 m wide V, 0.4 m deep: area 0.1 m2 spread over 1 m -> 0.1 m
    assert resolved_relief(0.4, 0.5, 0.5, 1.0) == pytest.approx(0.1)
    # a U section holds more area than a V of the same depth and width
    assert shape_factor("U", 4.0) == pytest.approx(0.8) and shape_factor("V", 4.0) == pytest.approx(0.5)


def test_visible_run_must_be_long_enough():
    s = np.arange(10, dtype=float)
    rel = np.array([0, 0.2, 0.2, 0, 0, 0.2, 0.2, 0.2, 0.2, 0.2])
    # the first run (1-2, 1 m long) is a dot; the second (5-9, 4 m) is a line
    assert visible_head_index(s, rel, 0.15, 3.0) == 5
    assert visible_head_index(s, rel, 0.15, 1.0) == 1
    assert visible_head_index(s, rel, 0.25, 1.0) == -1


def test_tapering_head_is_digitised_where_the_incision_becomes_visible():
    # depth ramps 0 -> 1 m over 10 m, width 2 m: relief >= 0.15 m from x = 1.5 m
    d = np.clip(np.arange(40) / 10.0, 0, 1)
    g = _gully(1, d, np.full(40, 2.0))
    h = digitised_heads([g], 0.0, "EPSG:32632", 1, VIS, 4.0)
    assert len(h) == 1
    assert h.geometry.x.iloc[0] == pytest.approx(2.0)


def test_shallow_narrow_gully_is_missed_and_wide_one_seen():
    narrow = _gully(1, np.full(30, 0.25), np.full(30, 0.8))  # relief 0.1 m < 0.15 m
    wide = _gully(2, np.full(30, 0.25), np.full(30, 2.5), y0=100.0)  # relief 0.25 m
    h = digitised_heads([narrow, wide], 0.0, "EPSG:32632", 1, VIS, 4.0)
    assert len(h) == 1 and h.geometry.y.iloc[0] == pytest.approx(100.0)
    # a noisier DSM (sigma_z 0.1 m, threshold 0.3 m) hides the wide one too
    h2 = digitised_heads([narrow, wide], 0.0, "EPSG:32632", 1, dict(VIS, dsm_sigma_z_m=0.1), 4.0)
    assert len(h2) == 0


def test_marginal_heads_are_missed_at_the_stated_rate():
    # relief 0.2 m: above 0.15 m but below 2 x 0.15 m -> marginal
    gs = [_gully(i, np.full(20, 0.2), np.full(20, 3.0), y0=10.0 * i) for i in range(400)]
    h = digitised_heads(gs, 0.0, "EPSG:32632", 3, dict(VIS, marginal_miss_rate=0.3), 4.0)
    assert 0.62 < len(h) / 400 < 0.78
    deep = [_gully(i, np.full(20, 1.0), np.full(20, 3.0), y0=10.0 * i) for i in range(50)]
    assert len(digitised_heads(deep, 0.0, "EPSG:32632", 3, dict(VIS, marginal_miss_rate=1.0), 4.0)) == 50


def test_false_heads_fall_on_tracks_away_from_gullies_and_positions_carry_the_error():
    grid = GridSpec(x0=0.0, y0=1000.0, cell=1.0, width=1000, height=1000, crs="EPSG:32632")
    lc = np.full((1000, 1000), CODE["grass"], dtype=np.uint8)
    lc[500:503, :] = CODE["track"]  # an E-W track at y = 497..500
    g = _gully(1, np.full(200, 1.0), np.full(200, 3.0), x0=0.0, y0=499.0)  # runs along x = 0..199 on the track
    h = digitised_heads([g], 0.0, "EPSG:32632", 5, dict(VIS, false_heads_per_km2=20.0), 4.0, landcover=lc, grid=grid)
    false = h.iloc[1:] if h.geometry.x.iloc[0] == pytest.approx(0.0) else h
    assert len(h) > 10
    xs, ys = h.geometry.x.to_numpy(), h.geometry.y.to_numpy()
    fx, fy = xs[xs > 1], ys[xs > 1]
    assert np.all((fy > 496) & (fy < 501)) and np.all(fx >= 199 + 15 - 1)
    assert len(false) == len(h) - 1
    # digitising error: SD 2 m per axis
    many = [_gully(i, np.full(20, 1.0), np.full(20, 3.0), x0=0.0, y0=50.0 * i) for i in range(300)]
    hh = digitised_heads(many, 2.0, "EPSG:32632", 9, VIS, 4.0)
    assert np.std(hh.geometry.x.to_numpy()) == pytest.approx(2.0, rel=0.15)
