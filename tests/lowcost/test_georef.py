"""Paper 004 georeferencing: tape file checks, ray triangulation, tape + Horn + tide shift."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from kitegully import InputError
from kitegully.dense.views import OrientedImage
from kitegully.georef.geometry import rotvec_to_matrix
from kitegully.georef.similarity import Similarity
from kitegully.lowcost.georef import georeference_rtk, georeference_tape_horn, read_tape, triangulate

TRIADS = [("T1a", "T1b", 2.0), ("T1b", "T1c", 2.0), ("T1c", "T1a", 2.0)]


def _write(tmp_path, rows):
    p = tmp_path / "tape.csv"
    pd.DataFrame(rows, columns=["from", "to", "length_m"]).to_csv(p, index=False)
    return p


def test_tape_file_naming_a_missing_target_is_one_sentence(tmp_path):
    p = _write(tmp_path, TRIADS[:2] + [("T1c", "T9z", 2.0)])
    with pytest.raises(InputError, match=r"tape\.csv: taped edge T1c-T9z names target T9z, which has no GPS position"):
        read_tape(p, {"T1a", "T1b", "T1c"})


def test_triad_with_one_side_is_one_sentence(tmp_path):
    p = _write(tmp_path, TRIADS + [("T2a", "T2b", 2.0)])
    with pytest.raises(InputError, match=r"the triad of targets T2a, T2b has 1 taped side\(s\); a triad needs its 3 sides taped"):
        read_tape(p, {"T1a", "T1b", "T1c", "T2a", "T2b"})


def test_complete_triads_are_read(tmp_path):
    p = _write(tmp_path, TRIADS)
    assert read_tape(p, {"T1a", "T1b", "T1c"}) == TRIADS


def _camera(C, look_at, f=1000.0):
    z = np.asarray(look_at, float) - C
    z /= np.linalg.norm(z)
    x = np.cross([0.0, 1.0, 0.0], z)
    x /= np.linalg.norm(x)
    R = np.vstack([x, np.cross(z, x), z])
    return OrientedImage("i", "i", 1000, 800, f, 500.0, 400.0, -0.02, 0.0, R, np.asarray(C, float))


def _click(img, X):
    Xc = img.R @ (X - img.C)
    x, y = Xc[0] / Xc[2], Xc[1] / Xc[2]
    d = 1 + img.k1 * (x * x + y * y)
    return img.f * x * d + img.cx, img.f * y * d + img.cy


def test_triangulation_of_clicks_recovers_a_point_with_distortion():
    X = np.array([1.0, 2.0, 0.5])
    imgs = {f"a{i}": _camera(np.array([i * 3.0, 0.0, 15.0]), X) for i in range(3)}
    rows = [{"image": k, "point": "P", "u_px": _click(im, X)[0], "v_px": _click(im, X)[1]} for k, im in imgs.items()]
    rows.append({"image": "unregistered", "point": "P", "u_px": 1.0, "v_px": 1.0})
    rows.append({"image": "a0", "point": "Q", "u_px": 10.0, "v_px": 10.0})          # one view: dropped
    out = triangulate(pd.DataFrame(rows), imgs)
    assert set(out) == {"P"}
    np.testing.assert_allclose(out["P"], X, atol=1e-6)


def test_tape_horn_and_tide_recover_a_known_placement():
    rng = np.random.default_rng(3)
    world = {}
    for i, (cx, cy) in enumerate([(10, 5), (20, 6), (30, 5)]):
        for j, a in enumerate(rng.uniform(0, 2 * np.pi) + np.arange(3) * 2 * np.pi / 3):
            world[f"T{i}{'abc'[j]}"] = np.array([cx + 2 / np.sqrt(3) * np.cos(a), cy + 2 / np.sqrt(3) * np.sin(a), 1.0 + 0.05 * i])
    edges = []
    for i in range(3):
        n = [f"T{i}{c}" for c in "abc"]
        edges += [(n[0], n[1], float(np.linalg.norm(world[n[0]] - world[n[1]]))),
                  (n[1], n[2], float(np.linalg.norm(world[n[1]] - world[n[2]]))),
                  (n[2], n[0], float(np.linalg.norm(world[n[2]] - world[n[0]])))]
    truth = Similarity(0.25, rotvec_to_matrix(np.array([[0.1, -0.2, 1.0]]))[0], np.array([5.0, -3.0, 2.0]))
    inv_R, inv_s = truth.R.T, 1 / truth.scale
    model = {k: inv_s * inv_R @ (v - truth.t) for k, v in world.items()}
    water_world = np.array([[12.0, 1.0, 0.16], [25.0, 1.5, 0.16]])
    water_model = (inv_s * (water_world - truth.t) @ inv_R.T)
    gps = {k: v + np.array([0.0, 0.0, 0.3]) for k, v in world.items()}            # GPS heights 0.3 m off
    sim, dz, res = georeference_tape_horn(model, gps, edges, water_model, 0.16)
    assert sim.scale == pytest.approx(truth.scale, rel=1e-9)
    assert dz == pytest.approx(-0.3, abs=1e-9)                                        # the tide removes the offset
    np.testing.assert_allclose(sim.apply(np.array(list(model.values()))), np.array(list(world.values())), atol=1e-9)
    glob = res[(res["scope"] == "global")]["residual_m"].iloc[0]
    local = res[(res["scope"] == "local")]["residual_m"].iloc[0]
    assert glob == pytest.approx(0.0, abs=1e-9) and local == pytest.approx(0.0, abs=1e-9)
    sim_r, res_r = georeference_rtk(model, world, edges)
    assert sim_r.scale == pytest.approx(truth.scale, rel=1e-9)
    assert set(res_r["scope"]) == {"global", "local", "target", "edge"}


def test_no_waterline_point_is_one_sentence():
    model = {f"T{i}": np.array(p, float) for i, p in enumerate([[0, 0, 0], [1, 0, 0], [0, 1, 0]])}
    edges = [("T0", "T1", 1.0), ("T1", "T2", 2**0.5), ("T2", "T0", 1.0)]
    with pytest.raises(InputError, match="no waterline point was triangulated"):
        georeference_tape_horn(model, model, edges, np.zeros((0, 3)), 0.16)


def test_levelling_on_the_waterline_removes_a_tilt():
    from kitegully.lowcost.georef import level_to_water
    rng = np.random.default_rng(5)
    u = rng.uniform(0, 40, 30)
    water = np.column_stack([u, 3.0 + rng.uniform(-2, 2, 30), np.full(30, 0.16)])   # level, ~1.2 m SD across
    tilt = rotvec_to_matrix(np.array([[0.03, -0.05, 0.0]]))[0]                       # a few degrees
    est = Similarity(1.0, tilt, np.array([0.0, 0.0, 2.0]))                           # the GPS-tilted block
    lev = level_to_water(est, water, min_spread_m=1.0)
    z = lev.apply(water)[:, 2]
    assert np.ptp(z) < 1e-9                                                         # the waterline is level again
    np.testing.assert_allclose(lev.R @ np.array([0, 0, 1.0]), [0, 0, 1.0], atol=1e-9)
    # points spread too little across: only the along-line tilt is fixed
    thin = np.column_stack([u, np.full(30, 3.0), np.full(30, 0.16)])
    lev2 = level_to_water(est, thin, min_spread_m=1.0)
    assert np.ptp(lev2.apply(thin)[:, 2]) < 1e-9
