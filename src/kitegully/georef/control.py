"""Ground control of one block: observations → triangulation → robust similarity → GCP
bundle adjustment, with quality flags and leave-one-out check points.

:func:`georeference_block` works on arrays (a :class:`~kitegully.georef.bundle.Block` and
the GCPs); :func:`kitegully.georef.stage.georeference` reads the files, calls it and writes
the products.

Frames: the SfM model frame (arbitrary), and the *local* frame = site CRS minus a round
``offset`` (kept so coordinates stay small for later stages). Every result in metres is
in the site CRS.

Flags (``flag`` column, ``;``-separated):

* ``missing_images:N`` – N observations name images that are not in the image folder;
* ``unregistered:N`` – N observations are in images SfM could not register;
* ``inconsistent_coords:D`` – rows of this GCP give coordinates up to D m apart;
* ``no_obs`` / ``single_obs`` – fewer than two usable observations: not used;
* ``ray_miss`` – its rays do not meet (triangulation reprojection error above
  ``qa.max_triangulation_px``): not used;
* ``outlier`` – disagrees with the others after the transform (residual above
  ``qa.max_residual_m`` while the others agree within it without it): not used;
* ``poor_fit`` – used, but its leave-one-out misfit (the solution without it, so it cannot
  have pulled the block towards itself) exceeds 3 σ on some axis, σ combining the survey
  sd, the click noise (``bundle.sigma_gcp_px``) propagated through the GCP's own rays
  (:func:`kitegully.georef.geometry.triangulation_covariance`) and the block's own
  placement error, estimated robustly from the other GCPs' leave-one-out residuals [I].
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from kitegully import InputError
from kitegully.georef.bundle import Block, BundleSettings, adjust
from kitegully.georef.gcp_io import GCP
from kitegully.georef.geometry import camera_centres, project, rotvec_to_matrix, triangulate, triangulation_covariance
from kitegully.georef.model import transform_block
from kitegully.georef.similarity import Similarity, plan_similarity, robust_similarity, tape_horn, umeyama
from kitegully.inputs.points import heights_are_placeholders
from kitegully.sfm.images import ImageInfo, to_sfm_pixels

if TYPE_CHECKING:
    from kitegully.georef.stage import GeorefParams, GeorefQA

log = logging.getLogger(__name__)

RESIDUAL_COLUMNS = ["gcp_id", "n_obs", "dx_m", "dy_m", "dz_m", "d3_m", "reproj_px", "used", "flag"]


@dataclass
class GcpObs:
    """A GCP's usable observations in the block (image rows and SfM pixels) and its flags."""

    gcp: GCP
    rows: np.ndarray
    xy: np.ndarray
    flags: list[str] = field(default_factory=list)


@dataclass
class GeorefResult:
    """Outcome of :func:`georeference_block`.

    Attributes
    ----------
    block : Block
        The adjusted block in the local frame.
    offset : ndarray (3,)
        Offset of the local frame (m), ``site = local + offset``: the GCPs' median plan position
        rounded to 100 m, and 0 in z.
    transform : Similarity
        Model → local similarity.
    residuals : DataFrame
        Residuals of every GCP after the adjustment (columns :data:`RESIDUAL_COLUMNS`).
    loo : DataFrame
        Leave-one-out residuals of the used GCPs (columns :data:`RESIDUAL_COLUMNS`).
    report : dict
        Run report: similarity scale, method, GSD (m), offset, residual statistics and, with
        the GCP bundle, the adjustment's own report.
    """

    block: Block
    offset: np.ndarray
    transform: Similarity
    residuals: pd.DataFrame
    loo: pd.DataFrame
    report: dict


def collect_observations(
    gcps: list[GCP], infos: list[ImageInfo], image_rows: dict[str, int], pixel_frame: str, sfm_frame: str, pixel_scale: float,
    coords_tolerance_m: float, pixel_offset_px: float = 0.0,
) -> list[GcpObs]:
    """Map each GCP's observations into the SfM frame, keeping those in registered images.

    ``image_rows`` maps the prepared image name (``ImageInfo.sfm_name``) to the block row.
    ``pixel_offset_px`` is added to the file's coordinates first: 0.5 when the file puts
    pixel centres at integer coordinates (COLMAP puts the image corner at 0).

    Parameters
    ----------
    gcps : list of GCP
        The GCPs read from the GCP file.
    infos : list of ImageInfo
        The images as the SfM stage prepared them.
    image_rows : dict of str to int
        Prepared image name → block row of the registered images.
    pixel_frame : str
        Frame of the file's pixel coordinates: ``stored`` or ``display``.
    sfm_frame : str
        Pixel frame the SfM worked in (``sfm.image_frame``).
    pixel_scale : float
        File pixels per full-resolution pixel.
    coords_tolerance_m : float
        Largest spread of a GCP's coordinates over its rows before it is flagged
        ``inconsistent_coords`` (m).
    pixel_offset_px : float
        Added to the file's pixel coordinates (px).

    Returns
    -------
    list of GcpObs
        One per GCP, in the order of ``gcps``: block rows, SfM pixels and flags.
    """
    by_name = {i.name: i for i in infos}
    out = []
    for g in gcps:
        rows, xy, missing, unreg = [], [], 0, 0
        for name, px in zip(g.images, g.pixels):
            info = by_name.get(name)
            if info is None:
                missing += 1
                continue
            if info.sfm_name not in image_rows:
                unreg += 1
                continue
            rows.append(image_rows[info.sfm_name])
            xy.append(to_sfm_pixels(px[None] + pixel_offset_px, info, pixel_frame, sfm_frame, pixel_scale)[0])
        flags = []
        if missing:
            flags.append(f"missing_images:{missing}")
        if unreg:
            flags.append(f"unregistered:{unreg}")
        if g.coord_spread_m > coords_tolerance_m:
            flags.append(f"inconsistent_coords:{g.coord_spread_m:.2f}")
        if len(rows) == 0:
            flags.append("no_obs")
        elif len(rows) == 1:
            flags.append("single_obs")
        out.append(GcpObs(g, np.array(rows, int), np.array(xy, float).reshape(-1, 2), flags))
    return out


def triangulate_gcps(block: Block, obs: list[GcpObs]) -> tuple[np.ndarray, np.ndarray]:
    """Each GCP intersected from its rays in the block's frame, and its RMS reprojection error (px)."""
    X = np.full((len(obs), 3), np.nan)
    rp = np.full(len(obs), np.nan)
    for k, o in enumerate(obs):
        if len(o.rows) < 2:
            continue
        ci = block.cam_of_image[o.rows]
        Xk, _ = triangulate(block.intr[ci], block.rv[o.rows], block.t[o.rows], o.xy, np.zeros(len(o.rows), int), 1)
        if not np.all(np.isfinite(Xk)):
            continue
        X[k] = Xk[0]
        p = project(block.intr[ci], block.rv[o.rows], block.t[o.rows], np.repeat(Xk, len(o.rows), 0))
        rp[k] = np.sqrt(np.mean(np.sum((p - o.xy) ** 2, axis=1)))
    return X, rp


def gcp_triangulation_covariance(block: Block, o: GcpObs, X: np.ndarray, sigma_px: float) -> np.ndarray:
    """Covariance (3×3, m²) of the GCP intersected from its observations with ``sigma_px`` click noise.

    Parameters
    ----------
    block : Block
        The block whose cameras observe the GCP.
    o : GcpObs
        The GCP's observations.
    X : ndarray (3,)
        The GCP's position in the block's frame.
    sigma_px : float
        Standard deviation of each pixel coordinate of a click (px).

    Returns
    -------
    ndarray (3, 3)
        Covariance (m²); all NaN where fewer than two rays or the geometry is singular.
    """
    ci = block.cam_of_image[o.rows]
    return triangulation_covariance(block.intr[ci], block.rv[o.rows], block.t[o.rows], X, sigma_px)


def reprojection_of(block: Block, o: GcpObs, X: np.ndarray) -> float:
    """RMS distance (px) between the measured pixels and the projection of ``X``.

    Parameters
    ----------
    block : Block
        The block whose cameras observe the GCP.
    o : GcpObs
        The GCP's observations.
    X : ndarray (3,)
        The point to project, in the block's frame.

    Returns
    -------
    float
        RMS reprojection error (px); NaN when the GCP has no observations.
    """
    if len(o.rows) == 0:
        return float("nan")
    ci = block.cam_of_image[o.rows]
    p = project(block.intr[ci], block.rv[o.rows], block.t[o.rows], np.repeat(X[None], len(o.rows), 0))
    return float(np.sqrt(np.mean(np.sum((p - o.xy) ** 2, axis=1))))


def _with_gcps(block: Block, obs: list[GcpObs], use: np.ndarray, start: np.ndarray) -> Block:
    b = block.copy()
    idx = np.flatnonzero(use)
    b.gcp_xyz = start[idx]
    b.gcp_obs_image = np.concatenate([obs[k].rows for k in idx]) if len(idx) else np.zeros(0, int)
    b.gcp_obs_gcp = np.concatenate([np.full(len(obs[k].rows), j) for j, k in enumerate(idx)]) if len(idx) else np.zeros(0, int)
    b.gcp_obs_xy = np.concatenate([obs[k].xy for k in idx]) if len(idx) else np.zeros((0, 2))
    return b


def solve(
    block: Block, obs: list[GcpObs], survey_local: np.ndarray, X_model: np.ndarray, use: np.ndarray,
    method: str, settings: BundleSettings, tape_edges: list[tuple[str, str, float]] | None = None,
) -> tuple[Block, Similarity, dict]:
    """One georeferencing solution from the GCPs in ``use``: similarity, then (optionally) the GCP bundle.

    Returns the block in the local frame, the model→local similarity and a report.

    Parameters
    ----------
    block : Block
        The SfM block in its model frame.
    obs : list of GcpObs
        The GCPs' observations.
    survey_local : ndarray (n_gcp, 3)
        Surveyed GCP positions in the local frame (m).
    X_model : ndarray (n_gcp, 3)
        The GCPs triangulated in the model frame.
    use : ndarray (n_gcp,) bool
        The GCPs the solution uses.
    method : str
        ``tape_horn``, ``similarity`` or ``gcp_bundle`` (similarity, then the GCP bundle).
    settings : BundleSettings
        Options of the GCP bundle adjustment (used by ``gcp_bundle`` only).
    tape_edges : list of (str, str, float) or None
        Taped distances ``(gcp_a, gcp_b, m)`` of the ``tape_horn`` method.

    Returns
    -------
    local : Block
        The block in the local frame.
    sim : Similarity
        Model → local similarity.
    report : dict
        Similarity scale and, with ``gcp_bundle``, the adjustment's own report.
    """
    ids = [o.gcp.gcp_id for o in obs]
    if method == "tape_horn":
        model_xyz = {ids[k]: X_model[k] for k in np.flatnonzero(use)}
        gps_xyz = {ids[k]: survey_local[k] for k in np.flatnonzero(use)}
        sim = tape_horn(model_xyz, gps_xyz, tape_edges or [])
    else:
        sim = umeyama(X_model[use], survey_local[use])
    local = transform_block(block, sim)
    report: dict = {"similarity_scale": sim.scale}
    if method == "gcp_bundle":
        start = sim.apply(np.nan_to_num(X_model))
        b = _with_gcps(local, obs, use, start)
        local, rep = adjust(b, survey_local[use], settings)
        report.update(rep)
    return local, sim, report


def georeference_block(
    block_model: Block,
    gcps: list[GCP],
    infos: list[ImageInfo],
    image_rows: dict[str, int],
    params: GeorefParams,
    sfm_frame: str,
    tape_edges: list[tuple[str, str, float]] | None = None,
    gcp_source: str = "GCP file",
) -> GeorefResult:
    """The whole georeferencing of a block with QA and leave-one-out; see the module docstring.

    Parameters
    ----------
    block_model : Block
        The SfM block in its model frame.
    gcps : list of GCP
        The GCPs read from the GCP file.
    infos : list of ImageInfo
        The images as the SfM stage prepared them.
    image_rows : dict
        Prepared image name → block row.
    params : GeorefParams
        Method parameters (the ``georef`` config section).
    sfm_frame : str
        Pixel frame the SfM worked in (``sfm.image_frame``).
    tape_edges : list of (str, str, float), optional
        Taped distances ``(gcp_a, gcp_b, m)`` of the ``tape_horn`` method.
    gcp_source : str
        The GCP file as the user gave it, named in error messages.

    Returns
    -------
    GeorefResult
        Block in the local frame, offset, transform, residual tables and report.

    Raises
    ------
    InputError
        Naming the GCPs when fewer than three are usable.

    Notes
    -----
    Phases: :func:`collect_observations`, :func:`triangulate_gcps`, :func:`select_gcps`,
    :func:`solve`, :func:`leave_one_out`, :func:`flag_poor_fits`, :func:`residual_tables`.
    Cost: (n_used + 1) bundle solutions.
    """
    qa = params.qa
    settings = params.bundle
    obs = collect_observations(
        gcps, infos, image_rows, params.gcp_pixel_frame, sfm_frame, params.gcp_pixel_scale, qa.coords_tolerance_m,
        params.gcp_pixel_offset_px,
    )
    survey = np.array([o.gcp.xyz for o in obs])
    offset = np.round(np.median(survey, axis=0) / 100.0) * 100.0
    offset[2] = 0.0
    survey_local = survey - offset
    X_model, rp_model = triangulate_gcps(block_model, obs)
    method = params.method
    plan_only = None
    if method != "tape_horn":
        if heights_are_placeholders(survey[:, 2]):
            survey_local, plan_only = plan_only_heights(block_model, obs, X_model, survey_local)
            method = "similarity"
        else:
            check_height_units(block_model, obs, X_model, survey_local, gcp_source)
    use = select_gcps(obs, X_model, rp_model, survey_local, qa, method)
    log.info("GCPs used: %s", ", ".join(obs[k].gcp.gcp_id for k in np.flatnonzero(use)))
    local, sim, report = solve(block_model, obs, survey_local, X_model, use, method, settings, tape_edges)

    gsd = ground_sampling_distance(local)
    X_final, _ = triangulate_gcps(local, obs)
    d_final = X_final - survey_local
    d_loo, rp_loo = leave_one_out(block_model, obs, survey_local, X_model, use, method, settings, tape_edges)
    flag_poor_fits(local, obs, use, X_final, d_final, d_loo, params)
    residuals, loo = residual_tables(local, obs, use, survey_local, d_final, d_loo, rp_loo)

    sig_survey = np.array([params.sigma_gcp_xy_m] * 2 + [params.sigma_gcp_z_m])
    report.update(_stats(residuals, loo, qa, obs, use, sig_survey))
    report["offset_m"] = offset.tolist()
    report["method"] = method
    report["gsd_m"] = gsd
    report["plan_only"] = plan_only is not None
    if plan_only is not None:
        _mark_plan_only(report, plan_only, params.method)
    return GeorefResult(local, offset, sim, residuals, loo, report)


# [I] Feet read as metres stretch every height difference by 1/0.3048 = 3.28; a block's own
# vertical scale is the horizontal one to well under 10 %, so a fitted ratio within 15 % of
# 3.28 (or of 0.3048 for metres declared as feet) cannot be anything else. The ratio is only
# judged where the GCPs' relief is several metres and its standard error small.
FEET_RATIO = 1.0 / 0.3048
MIN_RELIEF_FOR_UNITS_M = 2.0
MAX_RATIO_SE = 0.2


def height_ratio(block: Block, obs: list[GcpObs], X_model: np.ndarray, survey_local: np.ndarray) -> tuple[float, float, int]:
    """How much larger the surveyed height differences are than the block's own (fitted ratio).

    The block is scaled and levelled from the GCPs' plan coordinates
    (:func:`~kitegully.georef.similarity.plan_similarity`, cameras' mean viewing direction),
    then the surveyed heights are regressed on the block's heights with a plane (x, y) for
    the levelling error: ``z_survey = a + k z_block + b x + c y``. O(n).

    Parameters
    ----------
    block : Block
        The SfM block in its model frame.
    obs : list of GcpObs
        The GCPs' observations.
    X_model : ndarray (n, 3)
        The GCPs triangulated in the model frame.
    survey_local : ndarray (n, 3)
        Surveyed GCP positions in the local frame (m).

    Returns
    -------
    k, se, n : float, float, int
        Ratio, its standard error and the number of GCPs; NaN ratio when fewer than 5
        triangulated GCPs or less than ``MIN_RELIEF_FOR_UNITS_M`` of relief.
    """
    ok = np.array([len(o.rows) >= 2 and np.all(np.isfinite(X_model[k])) for k, o in enumerate(obs)])
    n = int(ok.sum())
    if n < 5:
        return float("nan"), float("nan"), n
    down, _ = mean_viewing_direction(block)
    sim = plan_similarity(X_model[ok], survey_local[ok, :2], down)
    lev = sim.apply(X_model[ok])
    z_block = lev[:, 2] - lev[:, 2].mean()
    if np.std(z_block) < MIN_RELIEF_FOR_UNITS_M / 2:
        return float("nan"), float("nan"), n
    xy = survey_local[ok, :2] - survey_local[ok, :2].mean(axis=0)
    A = np.column_stack([np.ones(n), z_block, xy])
    coef, *_ = np.linalg.lstsq(A, survey_local[ok, 2], rcond=None)
    dof = n - A.shape[1]
    if dof < 1:
        return float(coef[1]), float("nan"), n
    s2 = float(np.sum((A @ coef - survey_local[ok, 2]) ** 2) / dof)
    cov = s2 * np.linalg.pinv(A.T @ A)
    return float(coef[1]), float(np.sqrt(max(cov[1, 1], 0.0))), n


def check_height_units(block: Block, obs: list[GcpObs], X_model: np.ndarray, survey_local: np.ndarray, source: str) -> None:
    """Refuse GCP heights whose differences are 3.28 x (or 0.3048 x) those the photos show.

    Parameters
    ----------
    block : Block
        The SfM block in its model frame.
    obs : list of GcpObs
        The GCPs' observations.
    X_model : ndarray (n, 3)
        The GCPs triangulated in the model frame.
    survey_local : ndarray (n, 3)
        Surveyed GCP positions in the local frame (m).
    source : str
        The GCP file as the user gave it, named in the error message.

    Raises
    ------
    InputError
        Naming ``source`` and the fitted ratio, when the heights look like feet read as
        metres or metres declared as feet.
    """
    k, se, n = height_ratio(block, obs, X_model, survey_local)
    if not np.isfinite(k) or not np.isfinite(se) or se > MAX_RATIO_SE * k:
        return
    log.info("GCP height differences / block height differences: %.3f +- %.3f (%d GCPs)", k, se, n)
    if abs(k / FEET_RATIO - 1.0) < 0.15:
        raise InputError(f"{source}: the GCP height differences are {k:.2f} times those the photos show (fitted over {n} GCPs), "
                         "as if the heights were in feet; set inputs.z_units: ft (or us_ft) so they are converted")
    if abs(k * FEET_RATIO - 1.0) < 0.15:
        raise InputError(f"{source}: the GCP height differences are {k:.2f} times those the photos show (fitted over {n} GCPs), "
                         "as if metre heights had been declared as feet; check inputs.z_units")


def mean_viewing_direction(block: Block) -> tuple[np.ndarray, float]:
    """Mean optical axis of the block's cameras in its frame and its angular uncertainty.

    Returns the unit mean direction and the standard error of that mean (degrees): the
    spread of the individual axes about it over the square root of their number.
    """
    R = rotvec_to_matrix(block.rv)  # camera-from-world
    axes = R[:, 2, :]  # optical axis (camera +z) in the world frame, one row per image
    mean = axes.mean(axis=0)
    mean /= np.linalg.norm(mean)
    spread = np.degrees(np.arccos(np.clip(axes @ mean, -1.0, 1.0)))
    return mean, float(np.sqrt(np.mean(spread ** 2)) / np.sqrt(len(axes)))


def plan_only_heights(
    block: Block, obs: list[GcpObs], X_model: np.ndarray, survey_local: np.ndarray,
) -> tuple[np.ndarray, dict]:
    """Heights for GCPs surveyed in plan only (all heights one placeholder value).

    The block is levelled by its cameras' mean viewing direction and fitted to the GCPs'
    plan coordinates (:func:`~kitegully.georef.similarity.plan_similarity`); each
    triangulated GCP then gets the height the levelled block gives it, so the rest of the
    georeferencing (QA, leave-one-out) runs unchanged on consistent 3-D coordinates whose
    heights are relative to the placeholder value.

    [I] A kite rig (Picavet suspension) keeps the camera near nadir, swinging a few degrees
    about it; the mean of N optical axes is vertical to about spread/sqrt(N), which is the
    tilt the heights may carry (reported).

    Parameters
    ----------
    block : Block
        The SfM block in its model frame.
    obs : list of GcpObs
        The GCPs' observations.
    X_model : ndarray (n, 3)
        The GCPs triangulated in the model frame.
    survey_local : ndarray (n, 3)
        Surveyed GCP positions in the local frame (m); the first row's height is taken as the placeholder.

    Returns
    -------
    survey_local : (n, 3) array
        The survey coordinates with the heights replaced (a copy).
    info : dict
        ``z0`` (the placeholder), ``levelling_sd_deg``, ``n_cameras``, ``n_gcps``.
    """
    ok = np.array([len(o.rows) >= 2 and np.all(np.isfinite(X_model[k])) for k, o in enumerate(obs)])
    z0 = float(survey_local[0, 2])
    out = survey_local.copy()
    if ok.sum() < 2:
        return out, {"z0": z0, "levelling_sd_deg": float("nan"), "n_cameras": len(block.rv), "n_gcps": int(ok.sum())}
    down, sd_deg = mean_viewing_direction(block)
    sim = plan_similarity(X_model[ok], survey_local[ok, :2], down, z0)
    out[ok, 2] = sim.apply(X_model[ok])[:, 2]
    log.warning("GCP heights are all %g: georeferencing in plan only, levelled by %d cameras' mean viewing direction "
                "(+-%.2f deg)", z0, len(block.rv), sd_deg)
    return out, {"z0": z0, "levelling_sd_deg": sd_deg, "n_cameras": len(block.rv), "n_gcps": int(ok.sum())}


def _mark_plan_only(report: dict, info: dict, requested_method: str) -> None:
    """Say in the summary that the heights are relative and why the block is not trusted."""
    text = (f"the GCP heights are all {info['z0']:g} (placeholders, not surveyed): georeferenced in plan only, so "
            f"heights are relative to an arbitrary level and the block is levelled by the mean viewing direction of "
            f"its {info['n_cameras']} cameras (tilt uncertain by about {info['levelling_sd_deg']:.2f} deg); "
            "survey the GCP heights for absolute heights")
    if requested_method != "similarity":
        text += f" (the requested {requested_method} needs heights; a similarity on plan coordinates was used)"
    for key in ("gcp_rmse_z_m", "loo_rmse_z_m", "loo_rmse_3d_m"):
        report[key] = float("nan")
    report["height_datum"] = "relative"
    report["plan_only_levelling_sd_deg"] = info["levelling_sd_deg"]
    report["trusted"] = False
    report["trust_reasons"] = [text] + list(report.get("trust_reasons", []))
    report["diagnosis"] = "plan_only"
    report["diagnosis_text"] = text


def select_gcps(obs: list[GcpObs], X_model: np.ndarray, rp_model: np.ndarray, survey_local: np.ndarray, qa: GeorefQA,
                method: str) -> np.ndarray:
    """The GCPs the solution uses: seen in two registered images, rays meeting, no outlier.

    Appends ``ray_miss`` and ``outlier`` to the flags of those left out (the outlier test,
    a robust similarity, is skipped for ``tape_horn``, whose GPS positions are not
    accurate enough for it). Raises :class:`InputError` naming every GCP when fewer than
    three are usable. Returns a boolean mask over ``obs``.

    Parameters
    ----------
    obs : list of GcpObs
        The GCPs' observations; their flags are extended in place.
    X_model : ndarray (n, 3)
        The GCPs triangulated in the model frame (NaN where not triangulated).
    rp_model : ndarray (n,)
        RMS reprojection error of each triangulated GCP (px).
    survey_local : ndarray (n, 3)
        Surveyed GCP positions in the local frame (m).
    qa : GeorefQA
        QA limits (``max_triangulation_px``, ``max_residual_m``).
    method : str
        Georeferencing method; ``tape_horn`` skips the outlier test.

    Returns
    -------
    ndarray (n,) bool
        True for the GCPs the solution uses.
    """
    cand = np.array([len(o.rows) >= 2 and np.all(np.isfinite(X_model[k])) for k, o in enumerate(obs)])
    for k, o in enumerate(obs):
        if cand[k] and rp_model[k] > qa.max_triangulation_px:
            o.flags.append("ray_miss")
            cand[k] = False
    if cand.sum() < 3:
        bad = ", ".join(f"{o.gcp.gcp_id} ({';'.join(o.flags) or 'ok'})" for o in obs)
        raise InputError(f"fewer than three usable GCPs (need at least 3 seen in two registered images whose rays meet): {bad}")
    use = cand.copy()
    idx = np.flatnonzero(cand)
    if method != "tape_horn":
        _, inl = robust_similarity(X_model[idx], survey_local[idx], qa.max_residual_m)
        for k, ok in zip(idx, inl):
            if not ok:
                obs[k].flags.append("outlier")
                use[k] = False
    return use


def leave_one_out(
    block_model: Block, obs: list[GcpObs], survey_local: np.ndarray, X_model: np.ndarray, use: np.ndarray, method: str,
    settings: BundleSettings, tape_edges: list[tuple[str, str, float]] | None,
) -> tuple[dict[int, np.ndarray], dict[int, float]]:
    """Each used GCP checked against a solution without it (needs at least 3 others).

    Returns its misfit (local frame, m) and the RMS reprojection error (px) of its surveyed
    position, by index into ``obs``. Cost: one :func:`solve` per used GCP.

    Each solution starts, as the solution with every GCP does, from the similarity of the SfM
    block. (Starting from the adjusted block was tried in session 21: on the full-size site's
    516-photo block with every tie point it stopped after 2 iterations, because the relative
    cost decrease is dominated by the 1.2 M tie residuals, and its misfits differed by up to
    0.31 m from these.)

    Parameters
    ----------
    block_model : Block
        The SfM block in its model frame.
    obs : list of GcpObs
        The GCPs' observations.
    survey_local : ndarray (n, 3)
        Surveyed GCP positions in the local frame (m).
    X_model : ndarray (n, 3)
        The GCPs triangulated in the model frame.
    use : ndarray (n,) bool
        The GCPs the full solution uses.
    method : str
        Georeferencing method, as for :func:`solve`.
    settings : BundleSettings
        Options of the GCP bundle adjustment.
    tape_edges : list of (str, str, float) or None
        Taped distances ``(gcp_a, gcp_b, m)`` of the ``tape_horn`` method.

    Returns
    -------
    d_loo : dict of int to ndarray (3,)
        Misfit of each checked GCP: triangulated minus surveyed position (local frame, m).
    rp_loo : dict of int to float
        RMS reprojection error of each checked GCP's surveyed position (px).
    """
    n_use = int(use.sum())
    d_loo: dict[int, np.ndarray] = {}
    rp_loo: dict[int, float] = {}
    for k in np.flatnonzero(use) if n_use - 1 >= 3 else []:
        use_k = use.copy()
        use_k[k] = False
        loc_k, _, _ = solve(block_model, obs, survey_local, X_model, use_k, method, settings, tape_edges)
        Xk, _ = triangulate_gcps(loc_k, [obs[k]])
        d_loo[k] = Xk[0] - survey_local[k]
        rp_loo[k] = reprojection_of(loc_k, obs[k], survey_local[k])
    return d_loo, rp_loo


def flag_poor_fits(local: Block, obs: list[GcpObs], use: np.ndarray, X_final: np.ndarray, d_final: np.ndarray,
                   d_loo: dict[int, np.ndarray], params: GeorefParams) -> None:
    """Append ``poor_fit`` to used GCPs whose misfit exceeds 3 σ on some axis (module docstring).

    σ combines the survey SD, the click noise through the GCP's own rays and the block's
    placement error from the others' leave-one-out residuals.

    Parameters
    ----------
    local : Block
        The adjusted block in the local frame.
    obs : list of GcpObs
        The GCPs' observations; their flags are extended in place.
    use : ndarray (n,) bool
        The GCPs the solution uses.
    X_final : ndarray (n, 3)
        The GCPs triangulated in the adjusted block (local frame, m).
    d_final : ndarray (n, 3)
        Triangulated minus surveyed position of each GCP in the adjusted block (m).
    d_loo : dict of int to ndarray (3,)
        Leave-one-out misfits (m) by index into ``obs``.
    params : GeorefParams
        Method parameters: survey SDs (``sigma_gcp_xy_m``, ``sigma_gcp_z_m``) and
        ``bundle.sigma_gcp_px``.
    """
    sig_survey = np.array([params.sigma_gcp_xy_m] * 2 + [params.sigma_gcp_z_m])
    for k in np.flatnonzero(use):
        o = obs[k]
        sd_click = np.sqrt(np.diag(gcp_triangulation_covariance(local, o, X_final[k], params.bundle.sigma_gcp_px)))
        sd_block = _block_sd(d_loo, exclude=k)
        expected = np.sqrt(sig_survey**2 + sd_click**2 + sd_block**2)
        # tested where it cannot have pulled the block towards itself: its leave-one-out
        # misfit (the adjusted residual only when too few GCPs are left to leave one out)
        misfit = d_loo.get(k, d_final[k])
        log.info("%s: misfit %s m, expected sd %s m (survey, clicks through its rays, block from the others' "
                 "leave-one-out)", o.gcp.gcp_id, np.round(misfit, 3), np.round(expected, 3))
        if np.any(np.abs(misfit) > 3 * expected):
            o.flags.append("poor_fit")


def residual_tables(local: Block, obs: list[GcpObs], use: np.ndarray, survey_local: np.ndarray, d_final: np.ndarray,
                    d_loo: dict[int, np.ndarray], rp_loo: dict[int, float]) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The GCP residual table (every GCP) and the leave-one-out table (used GCPs), columns :data:`RESIDUAL_COLUMNS`.

    Parameters
    ----------
    local : Block
        The adjusted block in the local frame.
    obs : list of GcpObs
        The GCPs' observations.
    use : ndarray (n,) bool
        The GCPs the solution uses.
    survey_local : ndarray (n, 3)
        Surveyed GCP positions in the local frame (m).
    d_final : ndarray (n, 3)
        Triangulated minus surveyed position of each GCP in the adjusted block (m).
    d_loo : dict of int to ndarray (3,)
        Leave-one-out misfits (m) by index into ``obs``.
    rp_loo : dict of int to float
        Leave-one-out reprojection errors (px) by index into ``obs``.

    Returns
    -------
    residuals : DataFrame
        Residuals of every GCP after the adjustment.
    loo : DataFrame
        Leave-one-out residuals of the used GCPs (NaN where too few GCPs were left to leave one out).
    """
    rows = [_row(o, d_final[k], reprojection_of(local, o, survey_local[k]), bool(use[k])) for k, o in enumerate(obs)]
    residuals = pd.DataFrame(rows, columns=RESIDUAL_COLUMNS)
    loo_rows = []
    for k in np.flatnonzero(use):
        if k in d_loo:
            loo_rows.append(_row(obs[k], d_loo[k], rp_loo[k], False, extra="checkpoint"))
        else:
            loo_rows.append(_row(obs[k], np.full(3, np.nan), float("nan"), False, extra="too_few_gcps_to_leave_one_out"))
    return residuals, pd.DataFrame(loo_rows, columns=RESIDUAL_COLUMNS)


def _block_sd(d_loo: dict[int, np.ndarray], exclude: int) -> np.ndarray:
    """Robust per-axis sd (1.4826 x median |d|) of the other GCPs' leave-one-out residuals.

    How well the block itself is placed where no GCP holds it: the part of a GCP's misfit
    that neither its survey nor its clicks explain. Zero with fewer than three others.
    The median keeps one bad GCP from inflating it.
    """
    others = np.array([d for j, d in d_loo.items() if j != exclude and np.all(np.isfinite(d))])
    if len(others) < 3:
        return np.zeros(3)
    return 1.4826 * np.median(np.abs(others), axis=0)


def _row(o: GcpObs, d: np.ndarray, reproj: float, used: bool, extra: str = "") -> dict:
    flags = list(o.flags) + ([extra] if extra else [])
    return {
        "gcp_id": o.gcp.gcp_id, "n_obs": int(len(o.rows)), "dx_m": d[0], "dy_m": d[1], "dz_m": d[2],
        "d3_m": float(np.linalg.norm(d)) if np.all(np.isfinite(d)) else float("nan"),
        "reproj_px": reproj, "used": used, "flag": ";".join(flags),
    }


def _rmse(v: np.ndarray) -> float:
    v = v[np.isfinite(v)]
    return float(np.sqrt(np.mean(v**2))) if len(v) else float("nan")


def _stats(
    res: pd.DataFrame, loo: pd.DataFrame, qa: GeorefQA, obs: list[GcpObs], use: np.ndarray, sig_survey: np.ndarray | None = None,
) -> dict:
    """Accuracy figures and the trusted/untrusted verdict with its reasons.

    Besides ``trusted`` and ``trust_reasons`` (one sentence each), ``flagged_gcps`` lists
    every GCP the QA flagged with its flags, adjusted misfit, leave-one-out misfit and
    reprojection, and ``diagnosis`` tells apart:

    - ``trusted``: every check passed;
    - ``too_few_gcps``: fewer usable GCPs than ``qa.min_gcps_trusted`` or no leave-one-out;
    - ``inconsistent_with_photos``: GCPs whose rays miss each other, that fit no
      similarity, or whose leave-one-out misfit exceeds 3 sd of what their survey, clicks
      and the block explain, or a leave-one-out RMSE beyond 3 x the declared survey
      accuracy: the file disagrees with the photos (pixels, image names, scale or frame);
    - ``coordinates_metre_grade``: the GCPs agree with the photos within their declared
      survey accuracy (``sigma_gcp_xy_m``, ``sigma_gcp_z_m``), which is coarser than
      ``qa.required_accuracy_m``: the coordinates, not the photos, limit the accuracy.
    """
    u = res[res["used"]]
    out = {
        "n_gcps_in_file": len(obs),
        "n_gcps_used": int(use.sum()),
        "gcp_rmse_xy_m": _rmse(np.hypot(u["dx_m"].to_numpy(float), u["dy_m"].to_numpy(float))),
        "gcp_rmse_z_m": _rmse(u["dz_m"].to_numpy(float)),
        "loo_rmse_xy_m": _rmse(np.hypot(loo["dx_m"].to_numpy(float), loo["dy_m"].to_numpy(float))),
        "loo_rmse_z_m": _rmse(loo["dz_m"].to_numpy(float)),
        "loo_rmse_3d_m": _rmse(loo["d3_m"].to_numpy(float)),
    }
    loo_d3 = dict(zip(loo["gcp_id"], loo["d3_m"]))
    flagged_rows = res[res["flag"].str.contains("poor_fit|outlier|ray_miss|inconsistent_coords")]
    flagged = [
        {"gcp_id": r.gcp_id, "flags": r.flag, "misfit_3d_m": float(r.d3_m), "loo_misfit_3d_m": float(loo_d3.get(r.gcp_id, np.nan)),
         "reprojection_px": float(r.reproj_px)}
        for r in flagged_rows.itertuples()
    ]
    out["flagged_gcps"] = flagged
    reasons = []
    if out["n_gcps_used"] < qa.min_gcps_trusted:
        reasons.append(f"only {out['n_gcps_used']} GCPs usable (at least {qa.min_gcps_trusted} wanted)")
    if not np.isfinite(out["loo_rmse_3d_m"]):
        reasons.append("no leave-one-out check was possible")
    elif out["loo_rmse_3d_m"] > qa.required_accuracy_m:
        reasons.append(f"leave-one-out RMSE {out['loo_rmse_3d_m']:.2f} m exceeds the required {qa.required_accuracy_m} m")
    for f in flagged:
        what = []
        if "ray_miss" in f["flags"]:
            what.append(f"its rays miss each other by {f['reprojection_px']:.1f} px (limit {qa.max_triangulation_px} px)")
        if "outlier" in f["flags"]:
            what.append(f"it lies {f['misfit_3d_m']:.2f} m from the fit of the others (limit {qa.max_residual_m} m)")
        if "poor_fit" in f["flags"]:
            what.append(f"left out, the others put it {f['loo_misfit_3d_m']:.2f} m away, beyond 3 sd of what its survey, "
                        "clicks and the block explain")
        if "inconsistent_coords" in f["flags"]:
            what.append("its rows give different coordinates")
        reasons.append(f"GCP {f['gcp_id']} flagged ({f['flags']}): {'; '.join(what) or 'see the residual table'}")
    sig3 = float(np.linalg.norm(sig_survey)) if sig_survey is not None else float("nan")
    loo3 = out["loo_rmse_3d_m"]
    if not reasons:
        diagnosis, text = "trusted", "all checks passed"
    elif any(k in f["flags"] for f in flagged for k in ("ray_miss", "outlier", "poor_fit", "inconsistent_coords")) or (
        np.isfinite(loo3) and np.isfinite(sig3) and loo3 > 3 * sig3
    ):
        names = ", ".join(f["gcp_id"] for f in flagged)
        text = (f"the GCP file is inconsistent with the photos{' at ' + names if names else ''}"
                + (f" (leave-one-out RMSE {loo3:.2f} m against a declared survey accuracy of {sig3:.2f} m)"
                   if np.isfinite(loo3) and np.isfinite(sig3) else "")
                + ": check those points' coordinates, image names, pixel scale and frame")
        diagnosis = "inconsistent_with_photos"
    elif np.isfinite(loo3) and loo3 > qa.required_accuracy_m:
        diagnosis = "coordinates_metre_grade"
        text = (f"the GCPs agree with the photos within their declared survey accuracy ({sig3:.2f} m 3-D; leave-one-out "
                f"RMSE {loo3:.2f} m), but that is coarser than the required {qa.required_accuracy_m} m: the coordinates "
                "are metre-grade, not the photos at fault; survey the GCPs more precisely")
    else:
        diagnosis = "too_few_gcps"
        text = f"too few GCPs to check the block ({out['n_gcps_used']} usable, at least {qa.min_gcps_trusted} wanted)"
    out["trusted"] = not reasons
    out["trust_reasons"] = reasons
    out["diagnosis"] = diagnosis
    out["diagnosis_text"] = text
    return out


def ground_sampling_distance(block: Block) -> float:
    """Median ground sampling distance (m per SfM pixel): camera-to-point depth / focal length."""
    C = camera_centres(block.rv, block.t)
    if len(block.obs_image) == 0:
        return float("nan")
    depth = np.linalg.norm(block.points[block.obs_point] - C[block.obs_image], axis=1)
    f = block.intr[block.cam_of_image[block.obs_image], 0]
    return float(np.median(depth / f))
