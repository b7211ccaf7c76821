"""Sensitivity of the gully map to the smoothing σ and the depth threshold."""

from __future__ import annotations

import logging
from collections.abc import Sequence

import numpy as np
import pandas as pd

from kitegully.evaluate.network import NetworkScorer, area_scores
from kitegully.gully.depth import depth_map
from kitegully.gully.mapping import buffer_mask, final_map
from kitegully.gully.network import GullyNetwork, network_lines
from kitegully.gully.patches import depth_patches
from kitegully.io.raster import GridSpec

log = logging.getLogger(__name__)


def sensitivity_table(
    dem: np.ndarray,
    grid: GridSpec,
    network: GullyNetwork,
    sigmas_m: Sequence[float],
    thresholds_m: Sequence[float],
    min_volume_m3: float,
    buffer_m: float,
    connectivity: int,
    truncate: float,
    reference=None,
    tolerance_m: float = 5.0,
    domain=None,
    truth_mask: np.ndarray | None = None,
    workers: int = 1,
    known_depths: dict[float, np.ndarray] | None = None,
) -> pd.DataFrame:
    """Gully area, volume and (optionally) network and area scores for every (σ, threshold).

    The traced network does not depend on σ or the threshold (it comes from the filled
    DEM), so it is reused; the buffer is computed once, the reference is clipped and
    buffered once (:class:`kitegully.evaluate.network.NetworkScorer`).

    Returns
    -------
    DataFrame
        ``sigma_m, depth_threshold_m, n_gullies, gully_area_m2, gully_volume_m3`` and,
        with a reference network, ``good_fit_percent, false_positive_percent``; with a
        truth mask ``precision, recall, iou``.

    Notes
    -----
    One FFT smoothing per σ (O(n log n)) and O(n) per threshold; depth maps given in
    ``known_depths`` (σ in m → depth map, e.g. the stage's own depth.tif) are reused.
    """
    buf = buffer_mask(network.mask(), grid.cell, buffer_m)
    scorer = NetworkScorer(reference, domain) if reference is not None else None
    rows = []
    for sigma in sigmas_m:
        if known_depths and float(sigma) in known_depths:
            depth = known_depths[float(sigma)]
        else:
            _, depth = depth_map(dem, grid.cell, sigma, truncate, workers)
        for thr in thresholds_m:
            labels, _ = depth_patches(depth, grid.cell, thr, min_volume_m3, connectivity)
            gully = final_map(labels, buf)
            row = {
                "sigma_m": float(sigma),
                "depth_threshold_m": float(thr),
                "gully_area_m2": float(gully.sum()) * grid.cell**2,
                "gully_volume_m3": float(np.nansum(depth[gully], dtype=np.float64)) * grid.cell**2,
            }
            if reference is not None:
                ext = network_lines(network, grid, keep=gully)
                v = scorer.score(ext, tolerance_m).set_index("category")["percent"]
                row["good_fit_percent"] = float(v["good_fit"])
                row["false_positive_percent"] = float(v["false_positive"])
            if truth_mask is not None:
                s = area_scores(gully, truth_mask, grid.cell)
                row.update(precision=s["precision"], recall=s["recall"], iou=s["iou"])
            log.info("sensitivity σ = %.3g m, threshold = %.3g m: %s", sigma, thr, row)
            rows.append(row)
        del depth
    return pd.DataFrame(rows)
