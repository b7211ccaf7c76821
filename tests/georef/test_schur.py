"""The compiled normal-equation kernels against plain NumPy/SciPy on the synthetic block:
the Jacobians equal :func:`projection_jacobian`'s, and the Schur-complement step equals
the step of the full damped normal equations solved as one sparse system."""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix, diags
from scipy.sparse.linalg import spsolve

from kitegully.georef.bundle import BundleSettings, _damped_step, _normal_equations, _problem, _residual_state, projection_jacobian
from kitegully.georef.model import transform_block
from kitegully.georef.schur import point_order, weighted_jacobians
from kitegully.georef.similarity import umeyama

from .test_bundle import gcp_errors, synthetic_block


def _problem_and_state(refine=("f", "cx", "cy", "k1", "k2")):
    model, survey, *_ = synthetic_block()
    Xm = gcp_errors(model, np.zeros_like(survey))
    sim = umeyama(Xm, survey)
    model = transform_block(model, sim)
    model.gcp_xyz = sim.apply(Xm)
    pb = _problem(model, survey, BundleSettings(sigma_tie_px=0.3, sigma_gcp_px=0.5, refine=refine))
    state = (model.intr.copy(), model.rv.copy(), model.t.copy(), np.vstack([model.points, model.gcp_xyz]))
    return pb, state


def test_point_order_groups_observations_by_point():
    o_pt = np.array([2, 0, 2, 1, 0, 2])
    order, start = point_order(o_pt, 4)
    assert start.tolist() == [0, 2, 3, 6, 6]  # point 3 has no observation
    for p in range(4):
        assert (o_pt[order[start[p]:start[p + 1]]] == p).all()


def test_weighted_jacobians_equal_the_numpy_jacobian():
    pb, (intr, rv, t, pts) = _problem_and_state()
    weight = np.random.default_rng(0).uniform(0.5, 2.0, len(pb.o_img))
    Jc, Jx = weighted_jacobians(intr, pb.cam, rv, t, pb.o_img, pts, pb.o_pt, weight)
    _, Ji, Jp, JX = projection_jacobian(intr[pb.cam], rv[pb.o_img], t[pb.o_img], pts[pb.o_pt])
    # per column, against that column's scale: the rotation columns (up to ~5e3 px/rad) are sums of terms that
    # cancel, and the compiled and NumPy formulas round differently there (5e-10 of the scale measured on an AMD
    # EPYC, 1.7e-6 px absolute on an element of 3.1; elementwise atol 1e-6 failed there)
    for got, want in ((Jc, np.concatenate([Ji, Jp], axis=2) * weight[:, None, None]), (Jx, JX * weight[:, None, None])):
        scale = np.abs(want).max(axis=(0, 1))
        assert (np.abs(got - want).max(axis=(0, 1)) <= 1e-8 * np.maximum(scale, 1.0)).all()


def test_schur_step_equals_the_full_damped_normal_equations():
    """Reduced camera system + back-substitution = one sparse solve of (JᵀJ + λ diag) x = −Jᵀr
    over all unknowns (cameras, then points); f, k1 only, so some columns are not unknowns."""
    pb, state = _problem_and_state(refine=("f", "k1"))
    cost, r, w = _residual_state(pb, *state)
    ne = _normal_equations(pb, *state, w, r)
    lam = 1e-2
    dc, dp = _damped_step(pb, ne, lam)

    n, P, N = len(pb.o_img), pb.P, pb.N
    rows = np.repeat(np.arange(2 * n).reshape(n, 2, 1), 14, axis=2)
    cols = np.concatenate([np.broadcast_to(pb.cidx[:, None, :], (n, 2, 11)),
                           np.broadcast_to((P + 3 * pb.o_pt[:, None, None] + np.arange(3)), (n, 2, 3))], axis=2)
    vals = np.concatenate([ne.Jc, ne.Jx], axis=2)
    keep = cols >= 0
    J = coo_matrix((vals[keep], (rows[keep], cols[keep])), shape=(2 * n, P + 3 * N)).tocsr()
    rr = (r * np.sqrt(w)[:, None]).ravel()
    A = (J.T @ J).tolil()
    g = J.T @ rr
    # GCP position priors on the GCP points
    wp = np.tile(pb.prior_w, pb.ng)
    gi = P + 3 * pb.npt + np.arange(3 * pb.ng)
    A[gi, gi] = A[gi, gi].toarray().ravel() + wp
    g[gi] += ((state[3][pb.npt:] - pb.gcp_prior) * pb.prior_w).ravel()
    A = A.tocsr()
    d = A.diagonal()
    damp = np.concatenate([lam * (d[:P] + 1e-9), lam * d[P:] + 1e-12])
    x = spsolve((A + diags(damp)).tocsc(), -g)
    np.testing.assert_allclose(dc, x[:P], rtol=1e-6, atol=1e-9 * np.abs(x[:P]).max())
    np.testing.assert_allclose(dp, x[P:].reshape(N, 3), rtol=1e-6, atol=1e-9 * np.abs(x[P:]).max())
