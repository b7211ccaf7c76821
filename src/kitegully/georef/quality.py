"""GCP quality control: which GCPs a solution uses, which fit poorly, the residual tables and
the trusted/untrusted verdict (flags as in :mod:`kitegully.georef.control`).
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from kitegully import InputError
from kitegully.georef.bundle import Block
from kitegully.georef.observations import GcpObs, gcp_triangulation_covariance, reprojection_of, triangulated
from kitegully.georef.similarity import robust_similarity

if TYPE_CHECKING:
    from kitegully.georef.stage import GeorefParams, GeorefQA

log = logging.getLogger(__name__)

RESIDUAL_COLUMNS = ["gcp_id", "n_obs", "dx_m", "dy_m", "dz_m", "d3_m", "reproj_px", "used", "flag"]


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
    cand = triangulated(obs, X_model)
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


def trust_summary(
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
