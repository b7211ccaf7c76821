"""Gully heads against true heads: precision, recall and distances (evaluation only)."""

from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.spatial import cKDTree


def score_heads(
    detected_xy: np.ndarray, true_xy: np.ndarray, tolerance_m: float
) -> dict[str, float]:
    """Precision, recall and median distance of detected heads against true heads.

    One-to-one matching (Hungarian assignment on distances, pairs farther than
    ``tolerance_m`` do not match). Precision = matched / detected, recall = matched /
    true, ``median_distance_m`` over matched pairs (NaN without any), and
    ``median_nearest_m`` = median distance from each true head to the nearest detected one.
    O(m·n) memory for the distance matrix.

    Parameters
    ----------
    detected_xy, true_xy : ndarray (m, 2), (n, 2)
        Map coordinates (m) of the detected and the true heads.
    tolerance_m : float
        Largest distance of a matched pair (m).

    Returns
    -------
    dict
        ``detected, true, matched, precision, recall, median_distance_m, median_nearest_m,
        tolerance_m`` as floats; precision is NaN without detected heads, recall NaN without true ones.
    """
    d = np.asarray(detected_xy, float).reshape(-1, 2)
    t = np.asarray(true_xy, float).reshape(-1, 2)
    out = {"detected": float(len(d)), "true": float(len(t)), "matched": 0.0, "precision": np.nan, "recall": np.nan,
           "median_distance_m": np.nan, "median_nearest_m": np.nan, "tolerance_m": float(tolerance_m)}
    if len(t):
        out["recall"] = 0.0
    if len(d):
        out["precision"] = 0.0
    if not len(d) or not len(t):
        return out
    dist = np.hypot(d[:, None, 0] - t[None, :, 0], d[:, None, 1] - t[None, :, 1])
    cost = np.where(dist <= tolerance_m, dist, 1e9)
    ri, ci = linear_sum_assignment(cost)
    ok = dist[ri, ci] <= tolerance_m
    m = int(ok.sum())
    out.update(matched=float(m), precision=m / len(d), recall=m / len(t),
               median_distance_m=float(np.median(dist[ri, ci][ok])) if m else np.nan,
               median_nearest_m=float(np.median(cKDTree(d).query(t)[0])))
    return out
