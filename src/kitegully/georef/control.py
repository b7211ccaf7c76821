"""Ground control of one block: observations → triangulation → robust similarity → GCP
bundle adjustment, with quality flags and leave-one-out check points.

:func:`georeference_block` works on arrays (a :class:`~kitegully.georef.bundle.Block` and
the GCPs); :func:`kitegully.georef.stage.georeference` reads the files, calls it and writes
the products.

Its parts: the GCPs' observations in the block (:mod:`.observations`), GCP heights in the
wrong unit or never surveyed (:mod:`.heights`) and the quality control, residual tables and
verdict (:mod:`.quality`); this module solves and checks the block.

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
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from kitegully.georef.bundle import Block, BundleSettings, adjust
from kitegully.georef.gcp_io import GCP
from kitegully.georef.geometry import camera_centres
from kitegully.georef.heights import check_height_units, mark_plan_only, plan_only_heights
from kitegully.georef.model import transform_block
from kitegully.georef.observations import GcpObs, collect_observations, reprojection_of, triangulate_gcps
from kitegully.georef.quality import flag_poor_fits, residual_tables, select_gcps, trust_summary
from kitegully.georef.similarity import Similarity, tape_horn, umeyama
from kitegully.inputs.points import heights_are_placeholders
from kitegully.sfm.images import ImageInfo

if TYPE_CHECKING:
    from kitegully.georef.stage import GeorefParams

log = logging.getLogger(__name__)


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
        Residuals of every GCP after the adjustment (columns :data:`~kitegully.georef.quality.RESIDUAL_COLUMNS`).
    loo : DataFrame
        Leave-one-out residuals of the used GCPs (columns :data:`~kitegully.georef.quality.RESIDUAL_COLUMNS`).
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
    report.update(trust_summary(residuals, loo, qa, obs, use, sig_survey))
    report["offset_m"] = offset.tolist()
    report["method"] = method
    report["gsd_m"] = gsd
    report["plan_only"] = plan_only is not None
    if plan_only is not None:
        mark_plan_only(report, plan_only, params.method)
    return GeorefResult(local, offset, sim, residuals, loo, report)


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


def ground_sampling_distance(block: Block) -> float:
    """Median ground sampling distance (m per SfM pixel): camera-to-point depth / focal length."""
    C = camera_centres(block.rv, block.t)
    if len(block.obs_image) == 0:
        return float("nan")
    depth = np.linalg.norm(block.points[block.obs_point] - C[block.obs_image], axis=1)
    f = block.intr[block.cam_of_image[block.obs_image], 0]
    return float(np.median(depth / f))
