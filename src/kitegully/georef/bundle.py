"""Bundle adjustment with ground control: our own sparse least squares.

COLMAP's bundle adjustment has no GCP term, so the georeferencing step adjusts the block
again with three kinds of residuals, each divided by its standard deviation:

* tie-point reprojection errors, ``(x̂ − x) / σ_tie`` (px);
* GCP reprojection errors of the GCP image measurements, ``(x̂ − x) / σ_gcp_px``;
* GCP position priors, ``(X_gcp − X_survey) / σ_xyz`` (m), σ per axis from config.

Unknowns: every camera pose (rotation vector, translation), the shared intrinsics that
are refined (focal length, principal point, k1, k2), tie points and GCP points. The
problem is solved by Levenberg–Marquardt on the normal equations with the points
eliminated by the Schur complement (the classic sparse bundle adjustment): the reduced
camera system (intrinsics + poses) is dense but small, point blocks are 3×3. The
Jacobian is analytic except for the rotation columns (central differences). A Huber
weight (iteratively reweighted, threshold ``loss_scale`` σ) damps tie-point outliers;
GCP points are points with an additional position prior. Because the survey
fixes position, orientation and scale and the tie points tie the block together, a bent
block (wrong distortion start, dome) is straightened, which a similarity cannot do.

Cost per iteration: O(observations × 11²) to build the normal equations, O(Σ tracks² ×
11² × 3) to reduce them to the cameras (compiled, :mod:`kitegully.georef.schur`) plus
O(P³) for the reduced camera system of P = 5·cameras + 6·images unknowns.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np

from kitegully.georef.geometry import project, rotate
from kitegully.georef.schur import accumulate_normal_equations, chunk_count, point_order, point_steps, reduce_to_cameras, weighted_jacobians

log = logging.getLogger(__name__)

INTRINSIC_NAMES = ("f", "cx", "cy", "k1", "k2")


@dataclass
class Block:
    """A photogrammetric block in a metric local frame.

    Attributes
    ----------
    intr : (n_cameras, 5) intrinsics ``f, cx, cy, k1, k2`` (px, px, px, -, -).
    cam_of_image : (n_images,) camera index of each image.
    rv, t : (n_images, 3) camera-from-world rotation vectors and translations.
    points : (n_points, 3) tie points.
    obs_image, obs_point : (n_obs,) indices of each tie observation.
    obs_xy : (n_obs, 2) measured pixels.
    gcp_xyz : (n_gcp, 3) GCP positions (start values).
    gcp_obs_image, gcp_obs_gcp : (n_gobs,) indices of each GCP observation.
    gcp_obs_xy : (n_gobs, 2) measured GCP pixels.
    """

    intr: np.ndarray
    cam_of_image: np.ndarray
    rv: np.ndarray
    t: np.ndarray
    points: np.ndarray
    obs_image: np.ndarray
    obs_point: np.ndarray
    obs_xy: np.ndarray
    gcp_xyz: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    gcp_obs_image: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    gcp_obs_gcp: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    gcp_obs_xy: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))

    def copy(self) -> "Block":
        """A copy of the block with every array copied (no memory shared)."""
        return Block(**{k: np.array(v, copy=True) for k, v in self.__dict__.items()})

    def reprojection_rms(self) -> float:
        """RMS tie-point reprojection error (px)."""
        cam = self.cam_of_image[self.obs_image]
        p = project(self.intr[cam], self.rv[self.obs_image], self.t[self.obs_image], self.points[self.obs_point])
        return float(np.sqrt(np.mean(np.sum((p - self.obs_xy) ** 2, axis=1))))


@dataclass
class BundleSettings:
    """Weights and options of the GCP bundle adjustment (all from config).

    Attributes
    ----------
    sigma_tie_px, sigma_gcp_px : image measurement σ (px).
    sigma_gcp_xy_m, sigma_gcp_z_m : GCP survey σ (m).
    refine : names of intrinsics to refine (subset of f, cx, cy, k1, k2).
    loss : ``huber`` (robust) or ``linear`` (plain least squares) on image residuals.
    loss_scale : Huber threshold in σ units.
    max_iterations : Levenberg–Marquardt iterations at most.
    rel_tolerance : stop when an iteration lowers the cost by less than this fraction.
    """

    sigma_tie_px: float = 1.0
    sigma_gcp_px: float = 2.0
    sigma_gcp_xy_m: float = 0.02
    sigma_gcp_z_m: float = 0.03
    refine: tuple[str, ...] = ("f", "cx", "cy", "k1", "k2")
    loss: str = "huber"
    loss_scale: float = 3.0
    max_iterations: int = 50
    rel_tolerance: float = 1e-6


def projection_jacobian(intr: np.ndarray, rv: np.ndarray, t: np.ndarray,
                        X: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Pixels and their derivatives for each observation row.

    Returns ``p`` (n, 2), ``J_intr`` (n, 2, 5), ``J_pose`` (n, 2, 6) (rotation vector then
    translation) and ``J_X`` (n, 2, 3). Analytic except the rotation columns.
    The NumPy reference of :func:`kitegully.georef.schur.weighted_jacobians`, which
    :func:`adjust` uses (tests compare the two).

    Parameters
    ----------
    intr : ndarray (n, 5)
        Intrinsics ``f, cx, cy, k1, k2`` (px, px, px, -, -) of each observation's camera.
    rv, t : ndarray (n, 3)
        Camera-from-world rotation vector (rad) and translation of each observation.
    X : ndarray (n, 3)
        World point of each observation.

    Returns
    -------
    p : ndarray (n, 2)
        Projected pixels (px).
    J_intr : ndarray (n, 2, 5)
        Derivatives of the pixels by the intrinsics.
    J_pose : ndarray (n, 2, 6)
        Derivatives of the pixels by the rotation vector, then the translation.
    J_X : ndarray (n, 2, 3)
        Derivatives of the pixels by the world point.
    """
    xc = rotate(rv, X) + t
    z = xc[:, 2]
    u, v = xc[:, 0] / z, xc[:, 1] / z
    r2 = u * u + v * v
    f, k1, k2 = intr[:, 0], intr[:, 3], intr[:, 4]
    d = 1 + k1 * r2 + k2 * r2 * r2
    dd = k1 + 2 * k2 * r2  # d(d)/d(r2)
    p = np.column_stack([f * u * d + intr[:, 1], f * v * d + intr[:, 2]])
    n = len(X)
    Ji = np.zeros((n, 2, 5))
    Ji[:, 0, 0], Ji[:, 1, 0] = u * d, v * d
    Ji[:, 0, 1], Ji[:, 1, 2] = 1.0, 1.0
    Ji[:, 0, 3], Ji[:, 1, 3] = f * u * r2, f * v * r2
    Ji[:, 0, 4], Ji[:, 1, 4] = f * u * r2 * r2, f * v * r2 * r2
    # d pixel / d (u, v)
    A = np.empty((n, 2, 2))
    A[:, 0, 0] = f * (d + 2 * u * u * dd)
    A[:, 0, 1] = f * 2 * u * v * dd
    A[:, 1, 0] = f * 2 * u * v * dd
    A[:, 1, 1] = f * (d + 2 * v * v * dd)
    # d (u, v) / d xc
    B = np.zeros((n, 2, 3))
    B[:, 0, 0] = 1 / z
    B[:, 0, 2] = -u / z
    B[:, 1, 1] = 1 / z
    B[:, 1, 2] = -v / z
    Jxc = A @ B  # (n, 2, 3)
    Jp = np.empty((n, 2, 6))
    Jp[:, :, 3:] = Jxc
    h = 1e-6
    for k in range(3):
        e = np.zeros(3)
        e[k] = h
        dx = (rotate(rv + e, X) - rotate(rv - e, X)) / (2 * h)
        Jp[:, :, k] = np.einsum("nij,nj->ni", Jxc, dx)
    # d xc / d X = R: apply the rotation to the unit vectors
    JX = np.empty((n, 2, 3))
    for k in range(3):
        e = np.zeros((n, 3))
        e[:, k] = 1.0
        JX[:, :, k] = np.einsum("nij,nj->ni", Jxc, rotate(rv, e))
    return p, Ji, Jp, JX


@dataclass
class _Problem:
    """The fixed structure of one adjustment: observations, their weights and where each
    observation's camera and point parameters sit in the unknowns.

    Tie points and GCP points are one point set (GCPs after the ``npt`` tie points);
    observations are tie observations then GCP observations.
    """

    s: BundleSettings
    gcp_prior: np.ndarray
    nc: int  # cameras
    ni: int  # images
    npt: int  # tie points
    ng: int  # GCP points
    ref: np.ndarray  # refined intrinsic columns (indices into INTRINSIC_NAMES)
    cam: np.ndarray  # camera of each observation
    o_img: np.ndarray
    o_pt: np.ndarray  # index into the joint point set
    o_xy: np.ndarray
    o_sig: np.ndarray
    cidx: np.ndarray  # global camera-parameter index of each observation's 5+6 columns (-1: not refined)
    prior_w: np.ndarray
    n_tie: int
    n_g: int
    order: np.ndarray  # observations grouped by point (kitegully.georef.schur.point_order)
    start: np.ndarray

    @property
    def nri(self) -> int:
        return len(self.ref)

    @property
    def P(self) -> int:
        """Size of the reduced camera system (refined intrinsics + poses)."""
        return self.nc * self.nri + 6 * self.ni

    @property
    def N(self) -> int:
        return self.npt + self.ng


def _problem(block: Block, gcp_prior: np.ndarray, s: BundleSettings) -> _Problem:
    """Index the observations and parameters of ``block`` (phase 1 of :func:`adjust`)."""
    nc, ni, npt, ng = len(block.intr), len(block.rv), len(block.points), len(block.gcp_xyz)
    ref = np.array([INTRINSIC_NAMES.index(n) for n in s.refine], dtype=int)
    nri = len(ref)
    o_img = np.concatenate([block.obs_image, block.gcp_obs_image]).astype(int)
    o_pt = np.concatenate([block.obs_point, npt + block.gcp_obs_gcp]).astype(int)
    o_xy = np.concatenate([block.obs_xy, block.gcp_obs_xy])
    o_sig = np.concatenate([np.full(len(block.obs_image), s.sigma_tie_px), np.full(len(block.gcp_obs_image), s.sigma_gcp_px)])
    cam = block.cam_of_image[o_img]
    cidx = np.full((len(o_img), 11), -1)
    for j, r in enumerate(ref):
        cidx[:, r] = cam * nri + j
    cidx[:, 5:] = nc * nri + 6 * o_img[:, None] + np.arange(6)
    sig_prior = np.array([s.sigma_gcp_xy_m, s.sigma_gcp_xy_m, s.sigma_gcp_z_m])
    order, start = point_order(o_pt, npt + ng)
    return _Problem(s, gcp_prior, nc, ni, npt, ng, ref, cam, o_img, o_pt, o_xy, o_sig, cidx,
                    1.0 / sig_prior**2, len(block.obs_image), len(block.gcp_obs_image), order, start)


def _residual_state(pb: _Problem, intr, rv, t, pts) -> tuple[float, np.ndarray, np.ndarray]:
    """Cost, normalised image residuals (n, 2) and their Huber weights (n,)."""
    s = pb.s
    p = project(intr[pb.cam], rv[pb.o_img], t[pb.o_img], pts[pb.o_pt])
    r = (p - pb.o_xy) / pb.o_sig[:, None]
    rn = np.linalg.norm(r, axis=1)
    if s.loss == "huber":
        w = np.where(rn <= s.loss_scale, 1.0, s.loss_scale / np.maximum(rn, 1e-12))
        rho = np.where(rn <= s.loss_scale, rn**2, 2 * s.loss_scale * rn - s.loss_scale**2)
    else:
        w, rho = np.ones_like(rn), rn**2
    cost = 0.5 * rho.sum()
    if pb.ng:
        cost += 0.5 * float(np.sum((pts[pb.npt:] - pb.gcp_prior) ** 2 * pb.prior_w))
    return cost, r, w


@dataclass
class _Normal:
    """Gauss-Newton normal equations of one state: camera block ``U`` (P×P), point blocks
    ``V`` (N,3,3), gradients ``gc`` (P,) and ``gp`` (N,3), and the weighted Jacobians
    ``Jc`` (n,2,11) and ``Jx`` (n,2,3) from which the camera-point blocks ``W`` are formed
    point by point (:mod:`kitegully.georef.schur`)."""

    U: np.ndarray
    V: np.ndarray
    gc: np.ndarray
    gp: np.ndarray
    Jc: np.ndarray
    Jx: np.ndarray


def _normal_equations(pb: _Problem, intr, rv, t, pts, w, r) -> _Normal:
    """Gauss-Newton normal equations at ``(intr, rv, t, pts)`` with Huber weights ``w`` and
    normalised residuals ``r``. O(observations × 11²)."""
    Jc, Jx = weighted_jacobians(intr, pb.cam, rv, t, pb.o_img, pts, pb.o_pt, np.sqrt(w) / pb.o_sig)
    rr = r * np.sqrt(w)[:, None]
    U, V, gc, gp = accumulate_normal_equations(Jc, Jx, rr, pb.cidx, pb.order, pb.start, pb.P, chunk_count(pb.P))
    if pb.ng:
        V[pb.npt:] += np.diag(pb.prior_w)[None]
        gp[pb.npt:] += (pts[pb.npt:] - pb.gcp_prior) * pb.prior_w
    return _Normal(U, V, gc, gp, Jc, Jx)


def _damped_step(pb: _Problem, ne: _Normal, lam: float) -> tuple[np.ndarray, np.ndarray] | None:
    """Levenberg–Marquardt step with damping ``lam``: camera update by the Schur complement,
    then the point updates; ``None`` when the reduced system is singular.
    O(Σ tracks² × 11² × 3 + P³)."""
    U, V = ne.U, ne.V
    Ud = U + lam * np.diag(np.diag(U) + 1e-9)
    Vd = V + lam * (V * np.eye(3)[None]) + 1e-12 * np.eye(3)[None]
    Vinv = np.linalg.inv(Vd)
    WVW, WVg = reduce_to_cameras(ne.Jc, ne.Jx, pb.cidx, pb.order, pb.start, Vinv, ne.gp, pb.P, chunk_count(pb.P))
    try:
        dc = np.linalg.solve(Ud - WVW, -ne.gc + WVg)
    except np.linalg.LinAlgError:
        return None
    dp = point_steps(ne.Jc, ne.Jx, pb.cidx, pb.order, pb.start, Vinv, ne.gp, dc)
    return dc, dp


def _apply_step(pb: _Problem, intr, rv, t, pts, dc, dp):
    """Parameters after the update ``(dc, dp)`` (copies; the inputs are left unchanged)."""
    nc, nri = pb.nc, pb.nri
    intr_n, rv_n, t_n = intr.copy(), rv.copy(), t.copy()
    if nri:
        intr_n[:, pb.ref] += dc[: nc * nri].reshape(nc, nri)
    pose = dc[nc * nri:].reshape(pb.ni, 6)
    rv_n += pose[:, :3]
    t_n += pose[:, 3:]
    return intr_n, rv_n, t_n, pts + dp


def _levenberg_marquardt(pb: _Problem, state: tuple) -> tuple[tuple, float, float, np.ndarray, np.ndarray, int]:
    """Iterate damped Gauss-Newton steps from ``state = (intr, rv, t, pts)``.

    Returns the final state, initial and final cost, final residuals and weights and
    the number of iterations. Up to 10 damping increases per iteration; stops when no
    step lowers the cost or the relative decrease is below ``rel_tolerance``.
    """
    s = pb.s
    cost, r, w = _residual_state(pb, *state)
    cost0 = cost
    lam = 1e-3
    it = 0
    for it in range(1, s.max_iterations + 1):
        ne = _normal_equations(pb, *state, w, r)
        improved = False
        for _ in range(10):
            step = _damped_step(pb, ne, lam)
            if step is None:
                lam *= 10
                continue
            new = _apply_step(pb, *state, *step)
            cost_n, r_n, w_n = _residual_state(pb, *new)
            if np.isfinite(cost_n) and cost_n < cost:
                rel = (cost - cost_n) / max(cost, 1e-300)
                state, cost, r, w = new, cost_n, r_n, w_n
                lam = max(lam / 3, 1e-9)
                improved = True
                break
            lam *= 10
        if not improved or rel < s.rel_tolerance:
            break
    return state, cost0, cost, r, w, it


def _intrinsics_sd(pb: _Problem, state: tuple, w: np.ndarray, r: np.ndarray) -> np.ndarray:
    """A-priori SD (nc, nri) of the refined intrinsics: (JᵀJ)⁻¹ of the final state reduced
    to the camera block (NaN when singular).

    Points are eliminated with the pseudo-inverse of their 3 × 3 blocks: a point seen along
    nearly parallel rays has a near-singular block, whose plain inverse (1e12 and more)
    made the reduced system indefinite and the variances negative (clipped to 0) depending
    on the BLAS threads' rounding. The reduced camera system mixes units (f in pixels, k1
    dimensionless, rotations, metres), so it is scaled to unit diagonal (Jacobi) before the
    solve and the intrinsics' block of its inverse is scaled back. O(P³) for P camera unknowns."""
    nc, nri = pb.nc, pb.nri
    if not nri:
        return np.zeros((nc, 0))
    ne = _normal_equations(pb, *state, w, r)
    # eigenvalues below 1e-9 x the block's largest: a point direction the rays do not fix
    Vpinv = np.linalg.pinv(ne.V, rcond=1e-9, hermitian=True)
    WVW, _ = reduce_to_cameras(ne.Jc, ne.Jx, pb.cidx, pb.order, pb.start, Vpinv, ne.gp, pb.P, chunk_count(pb.P))
    S = ne.U - WVW
    m = nc * nri
    d = np.sqrt(np.abs(np.diag(S)))
    d[~(d > 0)] = 1.0
    Sn = S / d[:, None] / d[None, :]
    try:
        cov_c = np.linalg.solve(Sn, np.eye(len(S))[:, :m])[:m] / np.outer(d[:m], d[:m])
    except np.linalg.LinAlgError:
        return np.full((nc, nri), np.nan)
    var = np.diag(cov_c)
    return np.where(var > 0, np.sqrt(np.abs(var)), np.nan).reshape(nc, nri)


def adjust(block: Block, gcp_prior: np.ndarray, s: BundleSettings) -> tuple[Block, dict]:
    """Run the GCP bundle adjustment; returns the adjusted block and a report.

    ``gcp_prior`` (n_gcp, 3) are the surveyed GCP positions in the block's frame.
    Tie points and GCP points are one point set; GCP points carry the prior.
    Phases: :func:`_problem` (indexing), :func:`_levenberg_marquardt` (the solve),
    :func:`_intrinsics_sd` (precision), then the adjusted block and the report.

    Parameters
    ----------
    block : Block
        The block to adjust; it is left unchanged.
    gcp_prior : ndarray (n_gcp, 3)
        Surveyed GCP positions in the block's frame (m).
    s : BundleSettings
        Weights and options of the adjustment.

    Returns
    -------
    adjusted : Block
        A copy of ``block`` with the adjusted intrinsics, poses, tie points and GCP points.
    report : dict
        Problem size, initial and final cost, iterations, tie-point RMS (px) and the
        a-priori SD of the refined intrinsics per camera.
    """
    pb = _problem(block, gcp_prior, s)
    npt = pb.npt
    pts = np.vstack([block.points, block.gcp_xyz]) if pb.ng else block.points.copy()
    state0 = (block.intr.copy(), block.rv.copy(), block.t.copy(), pts)
    state, cost0, cost, r, w, it = _levenberg_marquardt(pb, state0)
    intr_sd = _intrinsics_sd(pb, state, w, r)
    intr, rv, t, pts = state
    out = block.copy()
    out.intr, out.rv, out.t = intr, rv, t
    out.points, out.gcp_xyz = pts[:npt], pts[npt:]
    n_tie, n_g = pb.n_tie, pb.n_g
    tie_res = r[:n_tie] * s.sigma_tie_px
    report = {
        "n_parameters": int(pb.P + 3 * pb.N),
        "n_residuals": int(2 * (n_tie + n_g) + 3 * pb.ng),
        "n_tie_observations": int(n_tie),
        "n_gcp_observations": int(n_g),
        "initial_cost": float(cost0),
        "final_cost": float(cost),
        "n_iterations": int(it),
        "tie_rms_px": float(np.sqrt(np.mean(np.sum(tie_res**2, axis=1)))) if n_tie else float("nan"),
        # a-priori standard deviations (from the configured sigmas) of the refined intrinsics, camera by camera
        "intrinsics_sd": [{INTRINSIC_NAMES[k]: float(intr_sd[c, j]) for j, k in enumerate(pb.ref)} for c in range(pb.nc)],
    }
    log.info("GCP bundle adjustment: %d parameters, cost %.4g -> %.4g in %d iterations, tie RMS %.3f px",
             report["n_parameters"], cost0, cost, it, report["tie_rms_px"])
    return out, report
