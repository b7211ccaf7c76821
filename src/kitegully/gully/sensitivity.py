"""Sensitivity of the gully map to the smoothing σ and the depth threshold.

The network scores of this table are NOT the paper protocol of ``network_validation.csv``
(:func:`kitegully.gully.validation.score_network`): they compare the extracted network
with the whole reference (every reference line, as the ``all (unfiltered)`` rows of
``network_validation_tolerances.csv``), at ``gully.validation.tolerance_m``, within the DEM
footprint, without a catchment clip. They show how the scores move with σ and the
threshold, not the paper's number.
"""

from __future__ import annotations

import logging
from concurrent.futures import ThreadPoolExecutor
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from kitegully.evaluate.network import NetworkScorer, area_scores, footprint
from kitegully.gully.depth import depth_map
from kitegully.gully.mapping import buffer_mask, final_map
from kitegully.gully.network import GullyNetwork, network_lines
from kitegully.gully.patches import depth_patches
from kitegully.gully.params import GullyParams
from kitegully.io.raster import GridSpec

if TYPE_CHECKING:
    from collections.abc import Callable

    import geopandas as gpd
    from shapely.geometry.base import BaseGeometry

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
    reference: gpd.GeoDataFrame | None = None,
    tolerance_m: float = 5.0,
    domain: BaseGeometry | Callable[[], BaseGeometry] | None = None,
    truth_mask: np.ndarray | None = None,
    workers: int = 1,
    known_depths: dict[float, np.ndarray] | None = None,
) -> pd.DataFrame:
    """Gully area, volume and (optionally) network and area scores for every (σ, threshold).

    The traced network does not depend on σ or the threshold (it comes from the filled
    DEM), so it is reused; the buffer is computed once, the reference is clipped and
    buffered once (:class:`kitegully.evaluate.network.NetworkScorer`).

    Parameters
    ----------
    domain : Polygon or callable, optional
        Where the networks are scored (the DEM footprint), or a function of no arguments
        that makes it: it is then called after the depth maps have started in their
        threads, so that it runs beside them.
    workers : int
        Threads. With 2 or more, the depth maps still to make are smoothed in parallel
        threads (up to ``workers`` at once, each FFT on one thread: the same values as one
        FFT on several threads, tested) while the buffer, the domain and the thresholds of
        the known σ are scored here.

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
    Memory: the DEM, the known depth map and up to ``workers`` depth maps being made
    (each about 6 float32 rasters at its peak).
    """
    known = known_depths or {}
    order = sorted(dict.fromkeys(float(s) for s in sigmas_m), key=lambda s: s not in known)
    todo = [s for s in order if s not in known]
    rows_of: dict[float, list[dict]] = {}
    parallel = workers > 1 and todo
    with ThreadPoolExecutor(max_workers=max(1, min(workers, len(todo)))) as pool:
        # the depth maps first (the longest work), then the buffer and domain beside them
        pending = {s: pool.submit(depth_map, dem, grid.cell, s, truncate, 1) for s in todo} if parallel else {}
        buf = buffer_mask(network.mask(), grid.cell, buffer_m)
        if callable(domain):
            domain = domain()
        scorer = NetworkScorer(reference, domain) if reference is not None else None
        for sigma in order:
            if sigma in known:
                depth = known[sigma]
            elif sigma in pending:
                depth = pending.pop(sigma).result()[1]
            else:
                depth = depth_map(dem, grid.cell, sigma, truncate, workers)[1]
            rows_of[sigma] = _threshold_rows(depth, sigma, thresholds_m, grid, network, buf, min_volume_m3,
                                             connectivity, reference, scorer, tolerance_m, truth_mask)
            del depth
    return pd.DataFrame([row for s in sigmas_m for row in rows_of[float(s)]])


def _threshold_rows(depth, sigma, thresholds_m, grid, network, buf, min_volume_m3, connectivity, reference, scorer,
                    tolerance_m, truth_mask) -> list[dict]:
    """Rows of :func:`sensitivity_table` for one depth map (one σ), one per threshold."""
    rows = []
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
    return rows


def gully_sensitivity(
    dem: np.ndarray,
    grid: GridSpec,
    network: GullyNetwork,
    depth: np.ndarray,
    mapping: GullyParams,
    sigmas_m: Sequence[float],
    thresholds_m: Sequence[float],
    tolerance_m: float,
    reference: gpd.GeoDataFrame | None = None,
    truth_mask: np.ndarray | None = None,
    workers: int = 1,
) -> pd.DataFrame:
    """The ``gully_sensitivity.csv`` table: :func:`sensitivity_table` with the stage's settings.

    Parameters
    ----------
    dem, grid : the mapping DEM and its grid.
    network : GullyNetwork
        The traced network of the ``gully_map`` run (independent of σ and the threshold).
    depth : ndarray
        The stage's own depth map at ``mapping.sigma_m`` (reused, not recomputed).
    mapping : GullyParams
        The mapping parameters (patch volume, buffer, connectivity, kernel truncation).
    sigmas_m, thresholds_m : sequences of float
        The σ and depth thresholds to try (``gully.sensitivity``).
    tolerance_m : float
        Matching tolerance of the network scores (``gully.validation.tolerance_m``).
    reference : GeoDataFrame, optional
        Reference network: network scores against all of it (see the module notes for
        how this differs from the paper protocol).
    truth_mask : ndarray of bool, optional
        Truth gully cells (twins): area scores.
    workers : int
        Threads: depth maps of several σ at once (:func:`sensitivity_table`).

    Returns
    -------
    DataFrame
        As :func:`sensitivity_table`.
    """
    def near_lines_footprint():
        # DEM footprint near the lines only: same clipping as the whole footprint, far cheaper;
        # made beside the depth maps (sensitivity_table calls it once they have started)
        return footprint(np.isfinite(dem), grid, near=[*reference.geometry, *network_lines(network, grid).geometry])

    domain = near_lines_footprint if reference is not None else None
    return sensitivity_table(
        dem, grid, network, sigmas_m, thresholds_m, mapping.min_patch_volume_m3, mapping.buffer_m, mapping.connectivity,
        mapping.truncate_sigmas, reference=reference, tolerance_m=tolerance_m, domain=domain, truth_mask=truth_mask,
        workers=workers, known_depths={float(mapping.sigma_m): depth},
    )
