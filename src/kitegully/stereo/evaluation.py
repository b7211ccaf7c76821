"""Evaluation of a stereo pair against the twin (reads the truth; never called by the processing).

How far the located marks lie from their true projections, the matcher's achieved disparity
precision measured on the true surface, and a DEM's error split into an orientation-type plane
and the matching-type rest.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Callable

import numpy as np

from kitegully.evaluate.dem import nmad

if TYPE_CHECKING:
    from kitegully.io.raster import GridSpec
    from kitegully.stereo.matching import Disparity
    from kitegully.stereo.processing import PairProcessor
    from kitegully.stereo.rectify import Rectification
    from kitegully.stereo.rig import StereoRig


def mark_error_px(pp: PairProcessor, truth: StereoRig, marks_xyz: np.ndarray) -> float:
    """Evaluation: RMS (px, per coordinate, both images) of the located marks minus their true projections.

    Parameters
    ----------
    pp : PairProcessor
        Pair built from images; ``info["marks_uv"]`` holds the located marks.
    truth : StereoRig
        The true cameras and poses.
    marks_xyz : ndarray (N, 3)
        True coordinates of the marks (m).

    Returns
    -------
    float
        RMS error (px).
    """
    ml, mr = pp.info["marks_uv"]
    e = np.r_[ml - truth.left.project(marks_xyz, truth.pose_left), mr - truth.right.project(marks_xyz, truth.pose_right)]
    return float(np.sqrt(np.mean(e ** 2)))


def pair_columns(pp: PairProcessor, truth: StereoRig, marks_xyz: np.ndarray) -> dict[str, float]:
    """The measurement columns of one pair: ties, mark precision from the noise, residuals, error against the truth.

    Parameters
    ----------
    pp : PairProcessor
        Pair built from images (:meth:`PairProcessor.from_images`).
    truth : StereoRig
        The true cameras and poses.
    marks_xyz : ndarray (N, 3)
        True coordinates of the marks (m).

    Returns
    -------
    dict
        ``ties_matched``, ``ties_inliers``, ``tie_sampson_rms_px``, ``mark_sigma_noise_px``,
        ``mark_abs_rms_mm`` (from ``pp.info``) and ``mark_error_px`` (:func:`mark_error_px`).
    """
    i = pp.info
    return {"ties_matched": i["ties_matched"], "ties_inliers": i["ties_inliers"], "tie_sampson_rms_px": i["tie_sampson_rms_px"],
            "mark_sigma_noise_px": i["mark_sigma_noise_px"], "mark_abs_rms_mm": i["mark_abs_rms_mm"],
            "mark_error_px": mark_error_px(pp, truth, marks_xyz)}


def matching_residual_px(rect: Rectification, disp: Disparity, truth: StereoRig, height: Callable, grid: GridSpec,
                         step_m: float = 0.002) -> dict[str, float]:
    """Evaluation: the matcher's achieved precision δ (px), measured directly against the twin's surface.

    Points of the true surface (every ``step_m`` over ``grid``) are projected through the true
    cameras into both photographs and mapped into the *processing's* rectified images; the
    matched disparity at the left position (bilinear, only where all four neighbours matched)
    minus ``x_l − x_r`` of those positions is the matching error. It is independent of the
    calibration and orientation errors (they move both the matched and the true positions
    alike), so it is the δ of the paper's Eq. 1 as this matcher achieves it on these images.

    Parameters
    ----------
    rect : Rectification
        The processing's rectification (estimated cameras and relative orientation).
    disp : Disparity
        The matched disparity of the left rectified image.
    truth : StereoRig
        The twin's true cameras and poses (evaluation only).
    height : callable
        True surface ``z = h(x, y)`` (m).
    grid : GridSpec
        Area to sample (the DEM's grid).
    step_m : float
        Sample spacing (m).

    Returns
    -------
    dict
        ``sigma_d_px`` (1.4826·MAD), ``bias_d_px`` (median), ``y_parallax_rms_px`` (RMS of
        ``y_l − y_r`` of the true points: the rectification's residual vertical parallax) and
        ``n`` (samples).

    Notes
    -----
    Cost: O(samples).
    """
    from scipy.ndimage import map_coordinates

    x0, y0, x1, y1 = grid.bounds
    X, Y = np.meshgrid(np.arange(x0 + step_m / 2, x1, step_m), np.arange(y0 + step_m / 2, y1, step_m))
    P = np.column_stack([X.ravel(), Y.ravel(), height(X.ravel(), Y.ravel())])
    a = rect.rectify_points(truth.left.project(P, truth.pose_left), "left")
    b = rect.rectify_points(truth.right.project(P, truth.pose_right), "right")
    d = np.where(disp.valid, disp.d, 0.0)
    coords = np.vstack([a[:, 1], a[:, 0]])
    dm = map_coordinates(d, coords, order=1, mode="constant", cval=np.nan)
    ok4 = map_coordinates(disp.valid.astype(float), coords, order=1, mode="constant", cval=0.0) > 0.999
    err = (dm - (a[:, 0] - b[:, 0]))[ok4]
    if err.size < 10:
        return {"sigma_d_px": float("nan"), "bias_d_px": float("nan"), "y_parallax_rms_px": float("nan"), "n": int(err.size)}
    med = float(np.median(err))
    return {"sigma_d_px": nmad(err), "bias_d_px": med,
            "y_parallax_rms_px": float(np.sqrt(np.mean((a[:, 1] - b[:, 1]) ** 2))), "n": int(err.size)}


def error_decomposition(dem: np.ndarray, ref: np.ndarray, grid: GridSpec) -> dict[str, float]:
    """Split a DEM's error into a plane (orientation-type: offset and tilt) and the rest (matching-type).

    Parameters
    ----------
    dem, ref : ndarray
        DEM and reference surface on ``grid`` (m); NaN in ``dem`` = no data.
    grid : GridSpec
        Their grid.

    Returns
    -------
    dict
        ``mean_error_mm`` (box-mean DEM − reference), ``tilt_mm_per_m`` (gradient magnitude of
        the best-fitting plane of the error), ``plane_mae_mm`` (MAE of that plane alone) and
        ``residual_mae_mm`` (MAE after removing it).
    """
    ok = np.isfinite(dem) & np.isfinite(ref)
    X, Y = np.meshgrid(*grid.cell_centres())
    e = (dem - ref)[ok]
    A = np.column_stack([np.ones(e.size), X[ok] - X[ok].mean(), Y[ok] - Y[ok].mean()])
    c, *_ = np.linalg.lstsq(A, e, rcond=None)
    plane = A @ c
    return {"mean_error_mm": 1e3 * float(e.mean()), "tilt_mm_per_m": 1e3 * float(np.hypot(c[1], c[2])),
            "plane_mae_mm": 1e3 * float(np.mean(np.abs(plane))), "residual_mae_mm": 1e3 * float(np.mean(np.abs(e - plane)))}

