"""Accuracy of a two-class map against a reference (Congalton 1991; Mayr et al. 2016).

Convention (documented because papers differ): the confusion matrix is
``C[mapped, reference]`` - rows are the classes of the map being assessed, columns the
reference classes.  Then

* user's accuracy of class k:      ``UA_k = C[k, k] / sum_j C[k, j]`` (row),
* producer's accuracy of class k:  ``PA_k = C[k, k] / sum_i C[i, k]`` (column),
* overall accuracy:                ``OA = trace(C) / sum(C)``.

Undefined ratios (an empty row or column) are NaN.
"""

from __future__ import annotations

import numpy as np

from kitegully.obia.classify import CLASS_NAMES, NODATA


def confusion_matrix(mapped: np.ndarray, reference: np.ndarray, n_classes: int = 2, valid: np.ndarray | None = None) -> np.ndarray:
    """Cell counts C[mapped, reference] over cells valid in both (codes 0..n-1). O(N)."""
    m = np.asarray(mapped).ravel().astype(np.int64)
    r = np.asarray(reference).ravel().astype(np.int64)
    ok = (m >= 0) & (m < n_classes) & (r >= 0) & (r < n_classes) & (m != NODATA) & (r != NODATA)
    if valid is not None:
        ok &= np.asarray(valid).ravel()
    return np.bincount(m[ok] * n_classes + r[ok], minlength=n_classes * n_classes).reshape(n_classes, n_classes)


def accuracies(conf: np.ndarray) -> dict:
    """User's, producer's (per class) and overall accuracy (fractions) from C[mapped, reference]."""
    c = np.asarray(conf, dtype=np.float64)
    diag = np.diag(c)
    with np.errstate(invalid="ignore", divide="ignore"):
        ua = diag / c.sum(axis=1)
        pa = diag / c.sum(axis=0)
        oa = diag.sum() / c.sum() if c.sum() > 0 else np.nan
    return {"users": ua, "producers": pa, "overall": float(oa)}


def accuracy_rows(scene: str, conf: np.ndarray, class_names: dict[int, str] = CLASS_NAMES) -> list[dict]:
    """Rows ``scene, class, users_accuracy, producers_accuracy, overall_accuracy`` in %."""
    acc = accuracies(conf)
    return [
        {
            "scene": scene,
            "class": class_names[k],
            "users_accuracy": 100.0 * acc["users"][k],
            "producers_accuracy": 100.0 * acc["producers"][k],
            "overall_accuracy": 100.0 * acc["overall"],
        }
        for k in sorted(class_names)
    ]


def area_error(area_auto: float, area_ref: float) -> tuple[float, float]:
    """(error %, error m²) of an automated area against the reference area.

    ``err% = (A_auto - A_ref) / A_ref * 100``; NaN when the reference area is 0.
    """
    err_m2 = float(area_auto - area_ref)
    err_pct = 100.0 * err_m2 / area_ref if area_ref > 0 else float("nan")
    return err_pct, err_m2
