"""GCP bundle adjustment on a synthetic kite block: a domed block is straightened.

The block: 4×5 nadir cameras 60 m above gently sloping ground, f = 1200 px, so the
ground sampling distance (GSD) is 60 / 1200 = 0.05 m. Tie observations carry 0.3 px
noise, GCP observations 0.5 px, survey 0.01 m. A dome (2 m at the block centre, 0 at its corners) and a
wrong distortion start (k1 = 0 instead of −0.05) bend the starting model. Tolerances are
in GSD: a straight block puts its GCPs within 1 GSD; the dome leaves decimetres after a
similarity.
"""

from __future__ import annotations

import numpy as np
import pytest

from kitegully.georef.bundle import Block, BundleSettings, adjust
from kitegully.georef.geometry import camera_centres, matrix_to_rotvec, project, rotvec_to_matrix, triangulate
from kitegully.georef.model import transform_block
from kitegully.georef.similarity import Similarity, umeyama

GSD = 0.05
W, H = 1600, 1200


def _ground(xy):
    return 100.0 + 0.05 * xy[:, 0] - 0.03 * xy[:, 1]


def synthetic_block(seed=3, dome=2.0, k1_start=0.0):
    rng = np.random.default_rng(seed)
    intr_true = np.array([[1200.0, 800.0, 600.0, -0.05, 0.01]])
    cx, cy = np.meshgrid(np.linspace(0, 120, 5), np.linspace(0, 90, 4))
    C = np.column_stack([cx.ravel(), cy.ravel(), np.zeros(cx.size)])
    C[:, 2] = _ground(C) + 60.0
    # nadir: camera x = east, camera y = south, camera z = down; small random tilts
    base = np.array([[1, 0, 0], [0, -1, 0], [0, 0, -1]], float)
    tilt = rotvec_to_matrix(rng.normal(0, 0.03, (len(C), 3)))
    R = tilt @ base
    rv = matrix_to_rotvec(R)
    t = -np.einsum("nij,nj->ni", R, C)
    pts_xy = rng.uniform([-20, -20], [140, 110], (1500, 2))
    P = np.column_stack([pts_xy, _ground(pts_xy) + rng.normal(0, 0.3, len(pts_xy))])
    gxy = np.array([[5, 5], [115, 8], [60, 45], [8, 85], [112, 82], [60, 5], [60, 85]], float)
    G = np.column_stack([gxy, _ground(gxy)])

    def observe(X, sigma):
        ii, jj, xy = [], [], []
        for i in range(len(C)):
            p = project(np.repeat(intr_true, len(X), 0), np.repeat(rv[i : i + 1], len(X), 0), np.repeat(t[i : i + 1], len(X), 0), X)
            zc = (rotvec_to_matrix(rv[i : i + 1])[0] @ X.T).T[:, 2] + t[i, 2]
            ok = (zc > 0) & (p[:, 0] > 0) & (p[:, 0] < W) & (p[:, 1] > 0) & (p[:, 1] < H)
            ii.append(np.full(ok.sum(), i)), jj.append(np.flatnonzero(ok)), xy.append(p[ok] + rng.normal(0, sigma, (ok.sum(), 2)))
        return np.concatenate(ii), np.concatenate(jj), np.concatenate(xy)

    oi, op, oxy = observe(P, 0.3)
    gi, gg, gxy_obs = observe(G, 0.5)
    survey = G + rng.normal(0, 0.01, G.shape)

    # The bent starting model: dome on points and centres, wrong k1, then an arbitrary similarity.
    centre = np.array([60.0, 45.0])

    def bend(X):
        r2 = np.sum((X[:, :2] - centre) ** 2, axis=1) / np.sum((np.array([0, 0]) - centre) ** 2)
        return X + np.column_stack([np.zeros((len(X), 2)), dome * (1 - r2)])

    Cb = bend(C)
    tb = -np.einsum("nij,nj->ni", R, Cb)
    intr0 = intr_true.copy()
    intr0[0, 3], intr0[0, 4] = k1_start, 0.0
    block = Block(intr0, np.zeros(len(C), int), rv, tb, bend(P), oi, op, oxy, np.zeros((len(G), 3)), gi, gg, gxy_obs)
    to_model = Similarity(0.37, rotvec_to_matrix(np.array([[0.2, -0.4, 1.1]]))[0], np.array([3.0, -7.0, 2.0]))
    inv = Similarity(1 / to_model.scale, to_model.R.T, -(to_model.R.T @ to_model.t) / to_model.scale)
    model = transform_block(block, to_model)
    return model, survey, G, C, inv


def gcp_errors(block, survey):
    ci = block.cam_of_image[block.gcp_obs_image]
    X, _ = triangulate(block.intr[ci], block.rv[block.gcp_obs_image], block.t[block.gcp_obs_image], block.gcp_obs_xy, block.gcp_obs_gcp, len(survey))
    return X - survey


def test_similarity_alone_leaves_the_dome_and_gcp_bundle_straightens_it():
    model, survey, G, C, _ = synthetic_block()
    # similarity alone: triangulate GCPs in the bent model, fit to the survey
    Xm = gcp_errors(model, np.zeros_like(survey)) + 0.0
    sim = umeyama(Xm, survey)
    bent = transform_block(model, sim)
    err_sim = gcp_errors(bent, survey)
    rmse_sim = np.sqrt(np.mean(np.sum(err_sim**2, axis=1)))
    assert rmse_sim > 2 * GSD, f"the dome should survive a similarity (RMSE {rmse_sim:.3f} m)"
    assert np.max(np.abs(err_sim[:, 2])) > 4 * GSD

    bent.gcp_xyz = sim.apply(Xm)
    adjusted, rep = adjust(bent, survey, BundleSettings(sigma_tie_px=0.3, sigma_gcp_px=0.5, sigma_gcp_xy_m=0.01, sigma_gcp_z_m=0.01, max_iterations=60))
    err = gcp_errors(adjusted, survey)
    assert np.sqrt(np.mean(err[:, 0] ** 2 + err[:, 1] ** 2)) <= 1 * GSD
    assert np.sqrt(np.mean(err[:, 2] ** 2)) <= 1.5 * GSD
    # the whole block is straight, not only the GCPs. Camera centres of a nadir block
    # are weaker than its ground points (position trades against attitude, height
    # against focal length over near-flat ground), so: plan within 3 GSD, and the
    # 2 m dome gone from the camera heights.
    Cest = camera_centres(adjusted.rv, adjusted.t)
    assert np.max(np.linalg.norm(Cest[:, :2] - C[:, :2], axis=1)) <= 3 * GSD
    dz = Cest[:, 2] - C[:, 2]
    assert np.ptp(dz) <= 4 * GSD  # no dome left in the camera heights (it was 2 m)
    assert adjusted.intr[0, 3] == pytest.approx(-0.05, abs=0.01)
    assert rep["tie_rms_px"] < 0.5


def test_intrinsics_sd_is_consistent_with_the_focal_length_error():
    """The reported sd of f comes from the normal equations with the true noise sigmas, so
    the adjusted f lies within 4 sd of the truth (1200 px), and the camera height error of
    the block mean follows f (the focal length / flying height correlation): mean dz ≈
    H·Δf/f within the scatter of the heights."""
    model, survey, G, C, _ = synthetic_block()
    Xm = gcp_errors(model, np.zeros_like(survey))
    sim = umeyama(Xm, survey)
    bent = transform_block(model, sim)
    bent.gcp_xyz = sim.apply(Xm)
    adjusted, rep = adjust(bent, survey, BundleSettings(sigma_tie_px=0.3, sigma_gcp_px=0.5, sigma_gcp_xy_m=0.01, sigma_gcp_z_m=0.01, max_iterations=60))
    sd = rep["intrinsics_sd"][0]
    assert set(sd) == {"f", "cx", "cy", "k1", "k2"}
    assert 0 < sd["f"] < 50 and np.isfinite(sd["f"])
    df = adjusted.intr[0, 0] - 1200.0
    assert abs(df) <= 4 * sd["f"]
    dz = camera_centres(adjusted.rv, adjusted.t)[:, 2] - C[:, 2]
    assert np.mean(dz) == pytest.approx(60.0 * df / 1200.0, abs=2 * np.std(dz) + GSD)


def test_problem_indexing_and_a_damped_step_lower_the_cost():
    """Phases of adjust: the parameter index of every observation, and one LM step."""
    from kitegully.georef.bundle import _apply_step, _damped_step, _normal_equations, _problem, _residual_state

    model, survey, *_ = synthetic_block()
    Xm = gcp_errors(model, np.zeros_like(survey)) + 0.0
    sim = umeyama(Xm, survey)
    model = transform_block(model, sim)
    model.gcp_xyz = sim.apply(Xm)
    s = BundleSettings(sigma_tie_px=0.3, sigma_gcp_px=0.5, refine=("f", "k1"))
    pb = _problem(model, survey, s)
    ni, npt, ng = len(model.rv), len(model.points), len(model.gcp_xyz)
    assert (pb.nri, pb.P, pb.N) == (2, 2 + 6 * ni, npt + ng)
    assert pb.n_tie == len(model.obs_image) and pb.n_g == len(model.gcp_obs_image)
    # columns of cx, cy, k2 are not refined; f and k1 of the one camera are unknowns 0 and 1
    assert (pb.cidx[:, [1, 2, 4]] == -1).all() and (pb.cidx[:, 0] == 0).all() and (pb.cidx[:, 3] == 1).all()
    # pose columns: 2 + 6 * image + (0..5); GCP observations point past the tie points
    assert np.array_equal(pb.cidx[:, 5:], 2 + 6 * pb.o_img[:, None] + np.arange(6))
    assert (pb.o_pt[pb.n_tie:] >= npt).all() and (pb.o_sig[pb.n_tie:] == 0.5).all()
    pts = np.vstack([model.points, model.gcp_xyz])
    state = (model.intr.copy(), model.rv.copy(), model.t.copy(), pts)
    cost, r, w = _residual_state(pb, *state)
    ne = _normal_equations(pb, *state, w, r)
    assert ne.U.shape == (pb.P, pb.P) and ne.V.shape == (pb.N, 3, 3) and ne.Jc.shape == (len(pb.o_img), 2, 11)
    np.testing.assert_allclose(ne.U, ne.U.T, rtol=1e-10, atol=1e-9)
    # observations grouped by point
    assert np.array_equal(np.sort(pb.o_pt[pb.order]), pb.o_pt[pb.order]) and pb.start[-1] == len(pb.o_pt)
    dc, dp = _damped_step(pb, ne, 1e-3)
    new = _apply_step(pb, *state, dc, dp)
    assert new[0] is not state[0] and np.array_equal(state[3], pts)  # inputs unchanged
    assert _residual_state(pb, *new)[0] < cost
