"""GCP heights the photos contradict or that were never surveyed.

:func:`check_height_units` refuses heights in feet read as metres (or the reverse) from the
ratio of surveyed to photographed height differences; :func:`plan_only_heights` gives GCPs
surveyed in plan only (every height one placeholder value) the heights of the block levelled
by its cameras' mean viewing direction, and :func:`mark_plan_only` says so in the report.
"""

from __future__ import annotations

import logging

import numpy as np

from kitegully import InputError
from kitegully.georef.bundle import Block
from kitegully.georef.geometry import rotvec_to_matrix
from kitegully.georef.observations import GcpObs, triangulated
from kitegully.georef.similarity import plan_similarity

log = logging.getLogger(__name__)


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
    ok = triangulated(obs, X_model)
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
    ok = triangulated(obs, X_model)
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


def mark_plan_only(report: dict, info: dict, requested_method: str) -> None:
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


