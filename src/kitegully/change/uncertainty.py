"""Per-cell elevation uncertainty of each epoch, its propagation into the DoD, and GCD's thresholds.

σ of an epoch comes from (in this order of preference in a site file, only one is given):
its independent checkpoints (SD of DEM − checkpoint, ``../shared/METHODS.md`` sect. 6 step 6),
a stated SD or RMSE (m), or an error raster (m per cell). The DoD's σ is
``σ_DoD = √(σ₁² + σ₂²)`` (errors of the two surveys independent; Wheaton et al. 2010 eq. 3).

Thresholds (Wheaton et al. 2010; GCD semantics, cells that fail are set to 0 change):

(a) ``min_lod``: |DoD| > LoD_min, one number for the whole site;
(b) ``propagated``: |DoD| > t·σ_DoD (t = 1 is GCD's "propagated error");
(c) ``probabilistic``: |DoD|/σ_DoD > z, z = Φ⁻¹((1 + confidence)/2) (95 % → 1.96);
(d) ``coherence``: the probabilistic prior p(A) = 2Φ(|DoD|/σ_DoD) − 1 updated by Bayes'
    theorem with the spatial coherence of the sign of change in a 5 × 5 window,
    ``p(A|E) = p(A)p(E|A) / [p(A)p(E|A) + (1 − p(A))(1 − p(E|A))]``, kept where
    p(A|E) ≥ confidence. p(E|A) rises linearly from ``p_low`` to ``p_high`` between
    ``n_low`` and ``n_high`` neighbours of the same sign.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import pandas as pd
from scipy import ndimage, stats

from kitegully import InputError
from kitegully.evaluate.dem import nmad, sd_without_blunders
from kitegully.change.dod import Epoch, resample
from kitegully.change.params import THRESHOLD_METHODS, ChangeParams
from kitegully.io.raster import GridSpec, Raster

log = logging.getLogger(__name__)


def checkpoint_errors(dem: Raster, checkpoints_csv: str | Path) -> pd.DataFrame:
    """DEM − checkpoint (m) at each checkpoint (bilinear DEM sample); columns id, x, y, z, dem, error."""
    path = Path(checkpoints_csv)
    if not path.exists():
        raise InputError(f"{path}: checkpoint file not found")
    cp = pd.read_csv(path)
    missing = [c for c in ("x", "y", "z") if c not in cp.columns]
    if missing:
        raise InputError(f"{path}: checkpoint file lacks column(s) {', '.join(missing)} (need id,x,y,z)")
    row, col = dem.grid.rowcol(cp["x"].to_numpy(float), cp["y"].to_numpy(float))
    z = ndimage.map_coordinates(dem.data.astype(np.float32), [row, col], order=1, mode="constant", cval=np.nan, prefilter=False)
    cp["dem"] = z
    cp["error"] = z - cp["z"].to_numpy(float)
    return cp


def epoch_sigma(epoch: Epoch, grid: GridSpec, outlier_nmad: float | None = 4.0) -> tuple[np.ndarray | float, dict[str, Any]]:
    """σ (m) of one epoch on ``grid``: a number, or an array for an error raster.

    Parameters
    ----------
    epoch : Epoch
        The DEM and its stated accuracy (``sd_m``, ``rmse_m``, ``error_raster`` or ``checkpoints``).
    grid : GridSpec
        The common grid (an error raster is resampled onto it).
    outlier_nmad : float or None
        Checkpoints only: a checkpoint whose error lies more than this many NMADs from the
        median is a blunder (a gross matching error at that spot: metres, not centimetres),
        counted and left out of σ, the SD of the others ([I] 4, the co-registration's
        outlier rule ``change.coregistration.outlier_nmad``; on an ensemble twin's epoch 2 a
        −9.7 m and a +1.1 m blunder among 462 checkpoints made an SD of 0.46 m out of an NMAD
        of 0.04 m; robust DEM accuracy after Höhle & Höhle 2009).
        None = the SD of all.

    Returns
    -------
    sigma : float or ndarray (H, W)
    info : dict
        ``epoch, source, sigma_m`` and for checkpoints ``n, mean_m, sd_m, rmse_m`` (of the
        kept ones), ``nmad_m`` and ``blunders`` (left out) and ``sd_all_m`` (SD of all).
    """
    acc = epoch.accuracy
    info: dict[str, Any] = {"epoch": epoch.name}
    if "sd_m" in acc:
        s = float(acc["sd_m"])
        info.update(source="stated SD", sigma_m=s)
        return s, info
    if "rmse_m" in acc:
        s = float(acc["rmse_m"])
        info.update(source="stated RMSE", sigma_m=s)
        return s, info
    if "error_raster" in acc:
        er = Raster.read(acc["error_raster"])
        arr = resample(er, grid)
        if np.nanmin(arr) < 0:
            raise InputError(f"{acc['error_raster']}: error raster holds negative σ values")
        info.update(source="error raster", sigma_m=float(np.nanmedian(arr)))
        return arr, info
    cp = checkpoint_errors(epoch.dem, acc["checkpoints"])
    e = cp["error"].to_numpy(float)
    e = e[np.isfinite(e)]
    if e.size < 3:
        raise InputError(f"{acc['checkpoints']}: fewer than 3 checkpoints fall on the DEM {epoch.path}; cannot state its accuracy")
    med = float(np.median(e))
    spread = nmad(e)
    s, keep = sd_without_blunders(e, outlier_nmad)
    kept = e[keep]
    src = "checkpoints (SD)" if kept.size == e.size else f"checkpoints (SD, {e.size - kept.size} blunders > {outlier_nmad:g} NMAD left out)"
    info.update(source=src, sigma_m=s, n=int(kept.size), mean_m=float(kept.mean()), sd_m=s,
                rmse_m=float(np.sqrt(np.mean(kept**2))), nmad_m=spread, blunders=int(e.size - kept.size),
                sd_all_m=float(e.std(ddof=1)))
    if kept.size < e.size:
        log.info("%s: %d of %d checkpoints are blunders (> %g NMAD = %.3f m from the median; largest %.2f m): sigma %.3f m "
                 "(SD of all %.3f m)", epoch.name, e.size - kept.size, e.size, outlier_nmad, outlier_nmad * spread,
                 float(e[np.argmax(np.abs(e - med))]), s, info["sd_all_m"])
    return s, info


def propagate(sigma1: np.ndarray | float, sigma2: np.ndarray | float, shape: tuple[int, int]) -> np.ndarray:
    """σ_DoD = √(σ₁² + σ₂²) as a float32 array of ``shape``.

    Parameters
    ----------
    sigma1, sigma2 : float or ndarray (H, W)
        σ of epoch 1 and epoch 2 (m).
    shape : tuple of int
        Shape ``(H, W)`` of the result.

    Returns
    -------
    ndarray (H, W) float32
        σ_DoD (m).
    """
    return np.broadcast_to(np.sqrt(np.square(sigma1) + np.square(sigma2)), shape).astype(np.float32)


def z_of_confidence(confidence: float) -> float:
    """Two-sided standard-normal quantile: 0.95 → 1.96."""
    return float(stats.norm.ppf(0.5 + confidence / 2.0))


def coherence_posterior(dod: np.ndarray, sigma: np.ndarray, params: ChangeParams) -> np.ndarray:
    """Posterior probability that change is real after GCD's spatial-coherence update.

    O(cells): two box filters of the sign indicators.

    Parameters
    ----------
    dod : ndarray (H, W)
        DoD (m); NaN is nodata.
    sigma : ndarray (H, W)
        σ_DoD (m).
    params : ChangeParams
        Reads the ``coherence_*`` keys.

    Returns
    -------
    ndarray (H, W) float32
        p(A|E); NaN where ``dod`` is NaN.
    """
    ok = np.isfinite(dod)
    w = params.coherence_window
    pos = (ok & (dod > 0)).astype(np.float32)
    neg = (ok & (dod < 0)).astype(np.float32)
    n_pos = ndimage.uniform_filter(pos, w, mode="constant") * w * w - pos
    n_neg = ndimage.uniform_filter(neg, w, mode="constant") * w * w - neg
    n_same = np.rint(np.where(dod > 0, n_pos, n_neg))
    frac = np.clip((n_same - params.coherence_n_low) / (params.coherence_n_high - params.coherence_n_low), 0.0, 1.0)
    p_e = params.coherence_p_low + frac * (params.coherence_p_high - params.coherence_p_low)
    with np.errstate(invalid="ignore", divide="ignore"):
        p_a = 2.0 * stats.norm.cdf(np.abs(dod) / sigma) - 1.0
        post = p_a * p_e / (p_a * p_e + (1.0 - p_a) * (1.0 - p_e))
    return np.where(ok, post, np.nan).astype(np.float32)


def detect(dod: np.ndarray, sigma: np.ndarray, params: ChangeParams) -> dict[str, np.ndarray]:
    """Boolean maps of detected change per threshold method (:data:`THRESHOLD_METHODS`).

    Parameters
    ----------
    dod : ndarray (H, W)
        DoD (m).
    sigma : ndarray (H, W)
        σ_DoD (m).
    params : ChangeParams
        Reads ``min_lod_m``, ``t_factor``, ``confidence`` and the ``coherence_*`` keys.

    Returns
    -------
    dict
        Method name to its ndarray (H, W) bool of detected cells (only cells where both inputs are finite).
    """
    a = np.abs(dod)

    ok = np.isfinite(dod) & np.isfinite(sigma)
    with np.errstate(invalid="ignore"):
        out = {
            "min_lod": ok & (a > params.min_lod_m),
            "propagated": ok & (a > params.t_factor * sigma),
            "probabilistic": ok & (a > z_of_confidence(params.confidence) * sigma),
            "coherence": ok & (coherence_posterior(dod, sigma, params) >= params.confidence),
        }
    assert tuple(out) == THRESHOLD_METHODS
    for k, m in out.items():
        log.info("threshold %s: %.2f %% of valid cells kept", k, 100.0 * m.sum() / max(ok.sum(), 1))
    return out


def thresholded(dod: np.ndarray, detected: np.ndarray) -> np.ndarray:
    """DoD with undetected cells set to 0 (NaN stays nodata), GCD's thresholded DoD."""
    return np.where(np.isfinite(dod), np.where(detected, dod, 0.0), np.nan).astype(np.float32)


def threshold_table(params: ChangeParams, sigma_dod: np.ndarray) -> pd.DataFrame:
    """What each threshold means in metres on this site (median σ_DoD)."""
    s = float(np.nanmedian(sigma_dod))
    z = z_of_confidence(params.confidence)
    return pd.DataFrame([
        ("min_lod", f"|DoD| > {params.min_lod_m:g} m", params.min_lod_m),
        ("propagated", f"|DoD| > {params.t_factor:g} x sigma_DoD", params.t_factor * s),
        ("probabilistic", f"|DoD| > {z:.3f} x sigma_DoD ({100 * params.confidence:g} %)", z * s),
        ("coherence", f"p(A|E) >= {params.confidence:g}, {params.coherence_window}x{params.coherence_window} window", np.nan),
    ], columns=["method", "rule", "threshold_at_median_sigma_m"])


def sigma_table(rows: list[Mapping[str, Any]], sigma_dod: np.ndarray) -> pd.DataFrame:
    """Per-epoch σ sources plus the propagated σ_DoD (median)."""
    df = pd.DataFrame(rows)
    factor = any(r.get("epoch") == "DoD factor" for r in rows)
    src = "propagated sqrt(s1^2 + s2^2)" + (" x factor (median over the cells)" if factor else "")
    extra = pd.DataFrame([{"epoch": "DoD", "source": src, "sigma_m": float(np.nanmedian(sigma_dod))}])
    return pd.concat([df, extra], ignore_index=True)
