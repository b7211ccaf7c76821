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


def confusion_matrix(mapped: np.ndarray, reference: np.ndarray, n_classes: int = 2, valid: np.ndarray | None = None,
                     chunk_cells: int = 1 << 22) -> np.ndarray:
    """Cell counts C[mapped, reference] over cells valid in both (codes 0..n-1).

    Parameters
    ----------
    mapped, reference : ndarray
        Class codes of the map and of the reference, same shape (NODATA and codes outside
        0..n-1 are not counted).
    n_classes : int
        Number of classes.
    valid : ndarray bool, optional
        Cells to count (same shape).
    chunk_cells : int
        Cells counted at a time: the int64 work arrays are this size, not the map's.

    Returns
    -------
    ndarray int64 (n_classes, n_classes)

    Notes
    -----
    O(N) time, O(``chunk_cells``) memory beyond the inputs. [I] Counted in chunks because
    the full site's 0.1 m kite map (318 M cells) made into int64 codes at once peaked at
    11.1 GB (session 19); a chunk of 4 M cells needs about 100 MB.
    """
    m_all = np.asarray(mapped).ravel()
    r_all = np.asarray(reference).ravel()
    if m_all.size != r_all.size:
        raise ValueError(f"mapped has {m_all.size} cells, the reference {r_all.size}")
    v_all = None if valid is None else np.asarray(valid, dtype=bool).ravel()
    counts = np.zeros(n_classes * n_classes, dtype=np.int64)
    step = max(1, int(chunk_cells))
    for start in range(0, m_all.size, step):
        part = slice(start, start + step)
        m = m_all[part].astype(np.int64)
        r = r_all[part].astype(np.int64)
        ok = (m >= 0) & (m < n_classes) & (r >= 0) & (r < n_classes) & (m != NODATA) & (r != NODATA)
        if v_all is not None:
            ok &= v_all[part]
        counts += np.bincount(m[ok] * n_classes + r[ok], minlength=n_classes * n_classes)
    return counts.reshape(n_classes, n_classes)


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
    """Rows ``scene, class, users_accuracy, producers_accuracy, overall_accuracy`` in %.

    Parameters
    ----------
    scene : str
        Scene name written in every row.
    conf : ndarray (n_classes, n_classes)
        Confusion matrix ``C[mapped, reference]`` (:func:`confusion_matrix`).
    class_names : dict
        Class code to name; one row per code, in code order.

    Returns
    -------
    list of dict
        One row per class; the overall accuracy is repeated in each.
    """
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
