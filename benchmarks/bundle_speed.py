#!/usr/bin/env python
"""Speed of the GCP bundle's normal equations: compiled kernels vs NumPy + SciPy sparse (issue 21).

At full size (epoch 2 of ``kamech_full``: 516 photos, 246 548 tie points, every one of them in
the bundle since session 21) one Levenberg-Marquardt solve took 2-2.5 min and the
georeferencing job, nine solves with the leave-one-out, 1 375 s. Session 22 moved the
normal equations and their Schur complement into compiled kernels
(:mod:`kitegully.georef.schur`). This script measures both on one synthetic block of the
full site's size, in one run:

* **reference**: the session-21 formulation: Jacobians with NumPy
  (:func:`kitegully.georef.bundle.projection_jacobian`), ``U`` by ``np.bincount`` of the
  per-observation 11 x 11 products, the camera-point blocks ``W`` as a SciPy sparse
  P x 3N matrix, the reduced system as ``W V^-1 W^T`` by sparse products;
* **kernels**: :func:`kitegully.georef.schur.weighted_jacobians`,
  :func:`~kitegully.georef.schur.accumulate_normal_equations`,
  :func:`~kitegully.georef.schur.reduce_to_cameras` and
  :func:`~kitegully.georef.schur.point_steps`, as :func:`kitegully.georef.bundle.adjust` uses them.

Both solve the same damped step; the table gives the wall time of building the normal
equations, of one damped step (reduction, dense solve, back-substitution), the step's largest
relative difference between the two, peak memory of each and the speed-up (kernels on one
thread, as the reference), the kernels' iteration on ``--threads`` threads (they run point
chunks in parallel, each with its own P x P sums), then the wall time of a whole adjustment
(kernels, one thread) for ``--iterations`` iterations.

The block: ``--photos`` nadir photos on a grid 150 m above ground (f 3500 px, 4000 x 3000 px),
``--points`` points on rough ground, each photo observing 45 % of the points in its footprint
(matching is incomplete), 8 GCPs; the start is perturbed (f +1 %, k1 0, poses and points).
Track lengths (mean ~3.5) are those of the real block to within a factor of two.

    PYTHONPATH=src .venv/bin/python benchmarks/bundle_speed.py --out results/benchmarks/bundle_speed.csv

Cost: generation O(photos x points); the reference step O(observations x 11 x 3 x track) in
SciPy, a few GB at full size.
"""

from __future__ import annotations

import argparse
import csv
import logging
import resource
import sys
import time
import tracemalloc
from pathlib import Path

import numba
import numpy as np
from scipy.sparse import coo_matrix

from kitegully.georef.bundle import Block, BundleSettings, _damped_step, _normal_equations, _problem, _residual_state, adjust, projection_jacobian
from kitegully.georef.geometry import matrix_to_rotvec, project, rotvec_to_matrix

log = logging.getLogger("bundle_speed")


def synthetic_block(n_photos: int, n_points: int, seed: int = 1) -> tuple[Block, np.ndarray]:
    """A nadir block of about ``n_photos`` photos and ``n_points`` points, and its surveyed GCPs."""
    rng = np.random.default_rng(seed)
    width, height = 4000, 3000
    intr = np.array([[3500.0, 2000.0, 1500.0, -0.05, 0.01]])
    nx = max(2, int(round(np.sqrt(n_photos * 1.1))))
    ny = max(2, int(round(n_photos / nx)))
    spacing = 60.0  # m; footprint 171 x 129 m at 150 m: ~65 % forward, ~55 % side overlap
    gx, gy = np.meshgrid(np.arange(nx) * spacing, np.arange(ny) * spacing * 0.8)
    C = np.column_stack([gx.ravel(), gy.ravel(), np.full(gx.size, 150.0)])
    nadir = np.array([[1, 0, 0], [0, -1, 0], [0, 0, -1]], float)
    R = rotvec_to_matrix(rng.normal(0, 0.03, (len(C), 3))) @ nadir
    rv = matrix_to_rotvec(R)
    t = -np.einsum("nij,nj->ni", R, C)
    X = np.column_stack([rng.uniform(0, gx.max(), n_points), rng.uniform(0, gy.max(), n_points), rng.normal(0, 2, n_points)])
    G = np.column_stack([rng.uniform(0, gx.max(), 8), rng.uniform(0, gy.max(), 8), np.zeros(8)])

    def observe(P, keep, noise):
        ii, jj, xy = [], [], []
        for i in range(len(C)):
            near = np.flatnonzero((np.abs(P[:, 0] - C[i, 0]) < 100) & (np.abs(P[:, 1] - C[i, 1]) < 80))
            p = project(np.repeat(intr, len(near), 0), np.repeat(rv[i:i + 1], len(near), 0), np.repeat(t[i:i + 1], len(near), 0), P[near])
            ok = (p[:, 0] > 0) & (p[:, 0] < width) & (p[:, 1] > 0) & (p[:, 1] < height) & (rng.random(len(near)) < keep)
            ii.append(np.full(ok.sum(), i)), jj.append(near[ok]), xy.append(p[ok] + rng.normal(0, noise, (ok.sum(), 2)))
        return map(np.concatenate, (ii, jj, xy))

    oi, op, oxy = observe(X, 0.45, 0.5)
    gi, gg, gxy = observe(G, 1.0, 0.5)
    intr0 = intr.copy()
    intr0[0, 0] *= 1.01
    intr0[0, 3] = 0.0
    block = Block(intr0, np.zeros(len(C), int), rv + rng.normal(0, 1e-4, rv.shape), t + rng.normal(0, 0.05, t.shape),
                  X + rng.normal(0, 0.05, X.shape), oi, op, oxy, G + rng.normal(0, 0.05, G.shape), gi, gg, gxy)
    return block, G


def reference_step(pb, state, w, r, lam):
    """The session-21 normal equations and damped step (NumPy + SciPy sparse)."""
    intr, rv, t, pts = state
    P, N, o_pt = pb.P, pb.N, pb.o_pt
    _, Ji, Jp, JX = projection_jacobian(intr[pb.cam], rv[pb.o_img], t[pb.o_img], pts[o_pt])
    sw = (np.sqrt(w) / pb.o_sig)[:, None, None]
    keep = pb.cidx >= 0
    Jc = np.where(keep[:, None, :], np.concatenate([Ji, Jp], axis=2) * sw, 0.0)
    Jx = JX * sw
    rr = r * np.sqrt(w)[:, None]
    ci = np.where(keep, pb.cidx, 0)
    bc = lambda idx, vals, size: np.bincount(idx.ravel(), weights=vals.ravel(), minlength=size)  # noqa: E731
    U = bc(ci[:, :, None] * P + ci[:, None, :], np.einsum("nki,nkj->nij", Jc, Jc), P * P).reshape(P, P)
    Wv = np.einsum("nki,nkj->nij", Jc, Jx)
    Wcols = 3 * o_pt[:, None, None] + np.arange(3)[None, None, :]
    W = coo_matrix((Wv.ravel(), (np.broadcast_to(ci[:, :, None], Wv.shape).ravel(), np.broadcast_to(Wcols, Wv.shape).ravel())), shape=(P, 3 * N)).tocsr()
    V = bc(o_pt[:, None, None] * 9 + (np.arange(3)[:, None] * 3 + np.arange(3))[None], np.einsum("nki,nkj->nij", Jx, Jx), 9 * N).reshape(N, 3, 3)
    gc = bc(ci, np.einsum("nki,nk->ni", Jc, rr), P)
    gp = bc(3 * o_pt[:, None] + np.arange(3), np.einsum("nki,nk->ni", Jx, rr), 3 * N).reshape(N, 3)
    if pb.ng:
        V[pb.npt:] += np.diag(pb.prior_w)[None]
        gp[pb.npt:] += (pts[pb.npt:] - pb.gcp_prior) * pb.prior_w
    t_normal = time.perf_counter()
    Ud = U + lam * np.diag(np.diag(U) + 1e-9)
    Vinv = np.linalg.inv(V + lam * (V * np.eye(3)[None]) + 1e-12 * np.eye(3)[None])
    rows = (3 * np.arange(N)[:, None, None] + np.arange(3)[None, :, None]).repeat(3, axis=2)
    cols = (3 * np.arange(N)[:, None, None] + np.arange(3)[None, None, :]).repeat(3, axis=1)
    WV = W @ coo_matrix((Vinv.ravel(), (rows.ravel(), cols.ravel())), shape=(3 * N, 3 * N)).tocsr()
    dc = np.linalg.solve(Ud - (WV @ W.T).toarray(), -gc + WV @ gp.ravel())
    dp = -(Vinv @ (gp + (W.T @ dc).reshape(N, 3))[:, :, None])[:, :, 0]
    return dc, dp, t_normal


def timed(fn):
    """(result, wall seconds, peak traced MB) of ``fn()``."""
    tracemalloc.start()
    t0 = time.perf_counter()
    out = fn()
    wall = time.perf_counter() - t0
    peak = tracemalloc.get_traced_memory()[1] / 2**20
    tracemalloc.stop()
    return out, wall, peak


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--photos", type=int, default=528, help="photos in the block (the full site's epochs: 773 and 516)")
    ap.add_argument("--points", type=int, default=247000, help="tie points (epoch 2 at full size: 246 548)")
    ap.add_argument("--iterations", type=int, default=5, help="iterations of the timed whole adjustment")
    ap.add_argument("--threads", type=int, default=2, help="numba threads of the kernels' parallel run (also timed on 1)")
    ap.add_argument("--out", type=Path, default=Path("results/benchmarks/bundle_speed.csv"))
    a = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(message)s")

    block, survey = synthetic_block(a.photos, a.points)
    s = BundleSettings()
    pb = _problem(block, survey, s)
    state = (block.intr.copy(), block.rv.copy(), block.t.copy(), np.vstack([block.points, block.gcp_xyz]))
    _, r, w = _residual_state(pb, *state)
    tracks = np.diff(pb.start)
    log.info("block: %d photos, %d points, %d observations (mean track %.2f), P = %d", len(block.rv), pb.N, len(pb.o_img), tracks.mean(), pb.P)
    lam = 1e-3
    # compile once (numba cache) before timing
    _damped_step(pb, _normal_equations(pb, *state, w, r), lam)

    numba.set_num_threads(1)
    (ne, t_k_normal, m_k_normal) = timed(lambda: _normal_equations(pb, *state, w, r))
    (step_k, t_k_step, m_k_step) = timed(lambda ne=ne: _damped_step(pb, ne, lam))
    del ne
    threads = max(1, min(a.threads, numba.config.NUMBA_NUM_THREADS))
    numba.set_num_threads(threads)
    (ne, t_p_normal, _) = timed(lambda: _normal_equations(pb, *state, w, r))
    (step_p, t_p_step, _) = timed(lambda ne=ne: _damped_step(pb, ne, lam))
    del ne
    diff_threads = max(np.abs(step_k[0] - step_p[0]).max() / np.abs(step_k[0]).max(), np.abs(step_k[1] - step_p[1]).max() / np.abs(step_k[1]).max())
    t0 = time.perf_counter()
    (ref, t_r_total, m_r) = timed(lambda: reference_step(pb, state, w, r, lam))
    dc_r, dp_r, t_normal_end = ref
    t_r_normal = t_normal_end - t0
    t_r_step = t_r_total - t_r_normal
    diff = max(np.abs(step_k[0] - dc_r).max() / np.abs(dc_r).max(), np.abs(step_k[1] - dp_r).max() / np.abs(dp_r).max())
    log.info("normal equations: kernels %.2f s, reference %.2f s; damped step: kernels %.2f s, reference %.2f s; step difference %.1e",
             t_k_normal, t_r_normal, t_k_step, t_r_step, diff)

    numba.set_num_threads(1)
    s_iter = BundleSettings(max_iterations=a.iterations, rel_tolerance=0.0)
    (_, rep), t_adjust, _ = timed(lambda: adjust(block, survey, s_iter))
    rows = [
        ("photos", len(block.rv), "", ""), ("points", pb.N, "", ""), ("observations", len(pb.o_img), "", ""),
        ("mean track length", round(float(tracks.mean()), 2), "", ""), ("camera unknowns P", pb.P, "", ""),
        ("normal equations wall s", round(t_k_normal, 3), round(t_r_normal, 3), round(t_r_normal / t_k_normal, 1)),
        ("damped step wall s", round(t_k_step, 3), round(t_r_step, 3), round(t_r_step / t_k_step, 1)),
        ("one iteration (normal + 1 step) wall s", round(t_k_normal + t_k_step, 3), round(t_r_total, 3), round(t_r_total / (t_k_normal + t_k_step), 1)),
        (f"one iteration on {threads} threads wall s (ratio: speed-up over 1 thread)", round(t_p_normal + t_p_step, 3), "", round((t_k_normal + t_k_step) / (t_p_normal + t_p_step), 2)),
        (f"step max relative difference, 1 vs {threads} threads", f"{diff_threads:.1e}", "", ""),
        ("peak traced memory MB", round(max(m_k_normal, m_k_step)), round(m_r), round(m_r / max(m_k_normal, m_k_step), 1)),
        ("step max relative difference", f"{diff:.1e}", "", ""),
        (f"adjust, {rep['n_iterations']} iterations, 1 thread, wall s", round(t_adjust, 1), "", ""),
        ("process peak RSS MB", round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024), "", ""),
    ]
    a.out.parent.mkdir(parents=True, exist_ok=True)
    with open(a.out, "w", newline="") as fh:
        wr = csv.writer(fh)
        wr.writerow(["item", "kernels", "reference (numpy + scipy.sparse)", "speed-up / ratio"])
        wr.writerows(rows)
    for row in rows:
        print(" | ".join(str(v) for v in row))
    return 0


if __name__ == "__main__":
    sys.exit(main())
