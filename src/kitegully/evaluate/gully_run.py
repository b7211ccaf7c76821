"""One gully-mapping run against a twin's reference and truth, as one table row (benchmarks).

Network lengths follow the paper's protocol (METHODS.md 1.6, as rule ``gully_validate``
applies it): only reference lines fed by a head on the DEM are scored, at each matching
tolerance; area scores compare the gully map with the true polygons cell by cell; heads
(when given) are scored one-to-one against the true heads.
"""

from __future__ import annotations

from typing import Iterable

import geopandas as gpd
import numpy as np

from kitegully.evaluate.heads import score_heads
from kitegully.evaluate.network import NetworkScorer, area_scores, footprint, rasterize_polygons, scored_reference
from kitegully.io.raster import GridSpec


def score_gully_run(
    gully: np.ndarray,
    extracted: gpd.GeoDataFrame,
    valid: np.ndarray,
    grid: GridSpec,
    reference: gpd.GeoDataFrame,
    truth_polygons: gpd.GeoDataFrame | None,
    tolerances_m: Iterable[float] = (2.0, 5.0, 15.0),
    reference_join_m: float = 3.0,
    heads_xy: np.ndarray | None = None,
    true_heads_xy: np.ndarray | None = None,
    head_tolerance_m: float = 15.0,
) -> dict[str, float]:
    """Good fit / false positive / false negative (% of the scored reference) per tolerance, IoU, head scores.

    Parameters
    ----------
    gully : ndarray bool (H, W)
        The final gully map (m).
    extracted : GeoDataFrame
        The traced network clipped to the map (rule output ``gully_network_mapped``).
    valid : ndarray bool (H, W)
        Valid DEM cells (the footprint).
    grid : GridSpec
    reference : GeoDataFrame
        The field (reference) network.
    truth_polygons : GeoDataFrame or None
        True gully polygons (twins), for the area scores.
    tolerances_m : floats
        Matching tolerances (m).
    reference_join_m : float
        ``gully.validation.reference_join_m``.
    heads_xy, true_heads_xy : ndarray (n, 2), optional
        Heads used and true heads, for :func:`kitegully.evaluate.heads.score_heads`.
    head_tolerance_m : float
        Matching distance of the head scores (m).

    Returns
    -------
    dict
        ``good_fit_<t>m_pct``, ``false_positive_<t>m_pct``, ``false_negative_<t>m_pct``,
        ``reference_m``, ``iou``, ``area_precision``, ``area_recall``, ``head_*``.
    """
    domain = footprint(valid, grid, near=[*reference.geometry, *extracted.geometry])
    scored, _not, _counts = scored_reference(reference, domain, float(reference_join_m))
    scorer = NetworkScorer([scored], domain, reference_all=reference)
    clipped = NetworkScorer(reference, domain).clip(extracted)
    row: dict[str, float] = {"reference_m": float(scored.length)}
    for t in tolerances_m:
        tab = scorer.score(extracted, float(t), clipped)
        pct = dict(zip(tab["category"], tab["percent"]))
        key = f"{t:g}"
        row[f"good_fit_{key}m_pct"] = float(pct["good_fit"])
        row[f"false_positive_{key}m_pct"] = float(pct["false_positive"])
        row[f"false_negative_{key}m_pct"] = float(pct["false_negative"])
    if truth_polygons is not None:
        truth = rasterize_polygons(truth_polygons, grid) & valid
        a = area_scores(gully & valid, truth, grid.cell)
        row.update(iou=a["iou"], area_precision=a["precision"], area_recall=a["recall"],
                   gully_area_m2=a["predicted_area_m2"], true_gully_area_m2=a["truth_area_m2"])
    if heads_xy is not None and true_heads_xy is not None:
        h = score_heads(heads_xy, true_heads_xy, head_tolerance_m)
        row.update({f"head_{k}": v for k, v in h.items() if k != "tolerance_m"})
    return row
