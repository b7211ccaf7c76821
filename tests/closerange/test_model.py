"""Sphere centres triangulated from unlabelled detection rays and paired with the survey (issue 20)."""

from __future__ import annotations

import numpy as np
import pytest

from kitegully import InputError
from kitegully.closerange.model import match_markers, triangulate_spheres, verify_spheres


def _ring_rays(S, n_cams=12, noise_rad=2e-4, seed=0):
    """Rays from a ring of cameras (radius 6 m, 3 m up) to the spheres, with angular noise, plus one stray ray per camera."""
    rng = np.random.default_rng(seed)
    O, D, pid = [], [], []
    for k in range(n_cams):
        a = 2 * np.pi * k / n_cams
        C = np.array([6 * np.cos(a), 6 * np.sin(a), 3.0])
        for s in S:
            d = s - C + rng.normal(0, noise_rad * np.linalg.norm(s - C), 3)
            O.append(C), D.append(d / np.linalg.norm(d)), pid.append(k)
        stray = rng.normal(0, 1, 3) - np.array([0, 0, 3.0])  # a bright pebble seen once
        O.append(C), D.append(stray / np.linalg.norm(stray)), pid.append(k)
    return np.array(O), np.array(D), np.array(pid)


S_TRUE = np.array([[2.0, 1.0, 0.1], [-2.5, 0.5, 0.3], [0.5, -3.0, 0.2], [-1.0, 2.5, 0.0]])


def test_unlabelled_rays_give_the_four_spheres_and_drop_stray_detections():
    O, D, pid = _ring_rays(S_TRUE)
    found = triangulate_spheres(O, D, pid, tolerance=0.01)
    assert len(found) == 4
    X = np.array([f[0] for f in found])
    err = np.min(np.linalg.norm(X[:, None] - S_TRUE[None], axis=2), axis=1)
    assert err.max() < 0.005  # 0.2 mrad at ~7 m is ~1.4 mm per ray
    assert all(len(f[1]) == 12 for f in found)


def test_model_spheres_are_paired_with_a_shuffled_survey_and_the_similarity_recovered():
    rng = np.random.default_rng(1)
    model = S_TRUE / 1.7  # arbitrary SfM scale, rotated and shifted below
    c, s = np.cos(0.6), np.sin(0.6)
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
    world = 1.7 * model @ R.T + np.array([545000.0, 4090000.0, 2300.0])
    order = [2, 0, 3, 1]
    survey = world[order] + rng.normal(0, 0.01, (4, 3))
    sim, rows, perm, res = match_markers(model, survey, ["S1", "S2", "S3", "S4"])
    assert [order[p] for p in perm] == rows  # survey row paired with the right model sphere
    assert abs(sim.scale - 1.7) < 0.01
    assert np.linalg.norm(res, axis=1).mean() < 0.03


def test_fewer_than_three_spheres_is_one_sentence():
    with pytest.raises(InputError, match=r"^only 2 sphere\(s\) triangulated in the model and 4 surveyed: at least 3 \(of S1, S2, S3, S4\)"):
        match_markers(S_TRUE[:2], S_TRUE, ["S1", "S2", "S3", "S4"])


def _world(model, scale=1.7, angle=0.6):
    c, s = np.cos(angle), np.sin(angle)
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
    return scale * model @ R.T + np.array([545000.0, 4090000.0, 2300.0])


def test_false_candidates_that_fit_better_in_rms_are_not_paired():
    """Scene 03's failure: extra triangulated candidates; the true four spheres win by inlier count, not by smallest RMS."""
    rng = np.random.default_rng(3)
    model = S_TRUE / 1.7
    survey = _world(model) + rng.normal(0, 0.015, (4, 3))
    # four false candidates (white stones) and a duplicate of sphere 0 offset by 30 cm in the model
    false = rng.uniform(-2.0, 2.0, (4, 3)) / 1.7
    cands = np.vstack([false[:2], model[[2, 0]], false[2:], model[[3, 1]], model[0] + 0.3 / 1.7])
    sim, rows, perm, res = match_markers(cands, survey, ["S1", "S2", "S3", "S4"])
    truth = {2: 2, 3: 0, 6: 3, 7: 1}  # candidate row -> survey row
    assert len(rows) == 4
    assert all(truth[r] == p for r, p in zip(rows, perm))
    assert np.linalg.norm(res, axis=1).max() < 0.06


def test_three_spheres_georeference_also_beside_a_misplaced_fourth():
    rng = np.random.default_rng(4)
    model = S_TRUE / 1.7
    survey = _world(model) + rng.normal(0, 0.01, (4, 3))
    cands = model.copy()
    cands[1] += np.array([0.5, 0.0, 0.0]) / 1.7  # sphere 1 measured 50 cm off
    sim, rows, perm, res = match_markers(cands, survey, ["S1", "S2", "S3", "S4"], 0.05, plausible=lambda s: abs(s.scale - 1.7) < 0.1)
    assert sorted(rows) == [0, 2, 3] and rows == perm and abs(sim.scale - 1.7) < 0.02


def test_no_assignment_within_the_survey_budget_is_one_sentence():
    model = S_TRUE / 1.7
    cands = model * np.array([1.3, 0.7, 1.0])  # a sheared model: no triple keeps its distances within the budget
    with pytest.raises(InputError, match=r"^no assignment of 3 of the 4 triangulated sphere\(s\) to the 4 surveyed \(S1, S2, S3, S4\) "
                                         r"fits the similarity within the survey budget of 0\.10 m"):
        match_markers(cands, _world(model), ["S1", "S2", "S3", "S4"])


def test_an_implausible_fit_is_skipped_for_the_next_and_rejected_when_none_is_left():
    rng = np.random.default_rng(6)
    model = S_TRUE / 1.7
    survey = _world(model) + rng.normal(0, 0.01, (4, 3))
    sim, rows, perm, res = match_markers(model, survey, ["S1", "S2", "S3", "S4"], plausible=lambda s: abs(s.scale - 1.7) < 0.1)
    assert len(rows) == 4
    with pytest.raises(InputError, match=r"^the \d+ assignment\(s\) of the 4 triangulated sphere\(s\) to the 4 surveyed .* put the cameras where they cannot have been"):
        match_markers(model, survey, ["S1", "S2", "S3", "S4"], plausible=lambda s: False)


def test_two_equally_good_assignments_are_ambiguous():
    model = S_TRUE[:3] / 1.7
    survey = _world(model)
    mirror = model.copy()
    mirror[:, 2] = -mirror[:, 2] + 5.0  # a second triple with the same distances, far from the first
    with pytest.raises(InputError, match=r"^\d+ different assignments of the 6 triangulated sphere\(s\) to the 3 surveyed .* the pairing is ambiguous"):
        match_markers(np.vstack([model, mirror]), survey, ["S1", "S2", "S3"])


def test_a_sphere_triangulated_twice_is_not_an_ambiguity():
    rng = np.random.default_rng(7)
    model = S_TRUE / 1.7
    survey = _world(model) + rng.normal(0, 0.005, (4, 3))
    cands = np.vstack([model, model[2] + np.array([0.02, 0.0, 0.0]) / 1.7])  # sphere 2 split into two copies 2 cm apart
    sim, rows, perm, res = match_markers(cands, survey, ["S1", "S2", "S3", "S4"], 0.05)
    assert len(rows) == 4 and sorted(perm) == [0, 1, 2, 3]


def test_a_sphere_has_one_radius_from_every_side_and_a_flat_patch_does_not():
    """Rays with the angular radius a 10 cm sphere shows at each camera's distance give radius 0.1; a flat
    white patch (10 cm across) on the ground shows a radius that changes with the viewing angle."""
    O, D, pid = _ring_rays(S_TRUE, noise_rad=1e-4)
    found = triangulate_spheres(O, D, pid, tolerance=0.01)
    label = np.tile(np.arange(len(S_TRUE) + 1), 12)  # per camera: the spheres in order, then the stray ray
    alpha = np.where(label < len(S_TRUE), np.arcsin(0.1 / np.linalg.norm(S_TRUE[label % len(S_TRUE)] - O, axis=1)), 0.01)
    ground = np.column_stack([np.random.default_rng(2).uniform(-4, 4, (400, 2)), np.zeros(400)])
    checks = verify_spheres(found, O, alpha, ground)
    assert all(c["sphere"] for c in checks)
    assert all(abs(c["radius"] - 0.1) < 0.003 for c in checks)
    # the flat patch: apparent angular radius ∝ sin(elevation of the view) / distance
    P = np.array([0.0, 0.0, 0.0])
    Ocams = np.array([[6 * np.cos(a), 6 * np.sin(a), 3.0] for a in np.linspace(0, 2 * np.pi, 12, endpoint=False)])
    Ocams[::2, :2] *= 2.5  # near and far sides of the ring (3-13 m in scene 05): the patch seen at 27° and 11° elevation
    dist = np.linalg.norm(Ocams - P, axis=1)
    a_patch = 0.1 * np.sqrt(Ocams[:, 2] / dist) / dist  # geometric mean of the ellipse's axes
    flat = verify_spheres([(P, np.arange(12))], Ocams, a_patch, ground)[0]
    assert not flat["sphere"] and flat["radius_spread"] > 0.15


def test_candidates_of_the_wrong_size_are_not_paired():
    """Three false candidates placed like three spheres but a third of their size do not pair (scene 05's chance fits)."""
    rng = np.random.default_rng(8)
    model = S_TRUE / 1.7
    survey = _world(model) + rng.normal(0, 0.01, (4, 3))
    cands = model[[0, 1, 2]]
    with pytest.raises(InputError, match="no assignment"):
        match_markers(cands, survey, ["S1", "S2", "S3", "S4"], 0.05, radii=np.full(3, 0.033 / 1.7), radius_m=0.1)
    sim, rows, perm, res = match_markers(cands, survey, ["S1", "S2", "S3", "S4"], 0.05, radii=np.full(3, 0.1 / 1.7), radius_m=0.1)
    assert sorted(rows) == [0, 1, 2]
