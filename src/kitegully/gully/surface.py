"""Surfaces the gully chain traces on: DSM holes filled, crowns, the tracing surface and object removal."""

from __future__ import annotations

import logging

import numpy as np

from kitegully.gully.crowns import crown_mask, excess_green, interpolate_under
from kitegully.gully.heads import HeadDetectionParams
from kitegully.gully.params import GullyParams
from kitegully.gully.relief import head_scale_ground, standing_above
from kitegully.io.raster import GridSpec
from kitegully.terrain.holes import interpolate_holes
from kitegully.terrain.smoothing import gaussian_smooth_fft

log = logging.getLogger(__name__)


def hole_filled(dem: np.ndarray, grid: GridSpec, params: GullyParams) -> tuple[np.ndarray, int]:
    """The DEM with holes smaller than ``water_min_area_m2`` interpolated (larger ones stay NaN: open water).

    Parameters
    ----------
    dem : ndarray (H, W) float32
        The DEM (m), NaN nodata.
    grid : GridSpec
    params : GullyParams

    Returns
    -------
    z : ndarray (H, W)
        The hole-filled DEM (heads are snapped and detected on it).
    n_holes : int
        Hole cells interpolated.
    """
    water_cells = None if params.water_min_area_m2 is None else int(np.ceil(params.water_min_area_m2 / grid.cell**2))
    return interpolate_holes(dem, water_cells)


def crowns_on(dem: np.ndarray, grid: GridSpec, params: GullyParams, incision: HeadDetectionParams, ortho: np.ndarray,
              workers: int = 1) -> np.ndarray:
    """The crown mask of ``gully.crowns`` (:func:`kitegully.gully.crowns.crown_mask`) on the DEM grid.

    Crowns are cells green in the orthophoto that stand more than ``relief_k``·max(σ_z, ρ)
    above the ground surface of the hole-filled DEM (the object threshold of
    :func:`remove_objects`: the incision threshold mirrored above the ground). O(n log n).

    Parameters
    ----------
    dem : ndarray (H, W) float32
        The DEM (m), NaN nodata.
    grid : GridSpec
        Grid of ``dem``.
    params : GullyParams
        ``water_min_area_m2`` and ``crowns`` are used.
    incision : HeadDetectionParams
        Ground surface and threshold of the crowns' height.
    ortho : ndarray (3, H, W) float32
        The orthophoto's R, G, B on the DEM grid (:func:`kitegully.gully.inputs.read_orthophoto_on_grid`).
    workers : int
        FFT threads.

    Returns
    -------
    ndarray (H, W) bool
        The crown mask.
    """
    zi, _ = hole_filled(dem, grid, params)
    ref = head_scale_ground(zi, grid.cell, incision, workers)
    ground, rough = ref.ground, ref.rough
    thr = incision.relief_k * max(incision.dsm_sigma_z_m, rough)
    mask, _info = crown_mask(zi, excess_green(ortho), ground, thr, grid.cell, params.crowns)
    return mask


def tracing_surface(
    dem: np.ndarray, grid: GridSpec, params: GullyParams, workers: int = 1,
    incision: HeadDetectionParams | None = None,
    hidden: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, int]:
    """The surface the network is traced on (steps f-g before the fill).

    Holes smaller than ``water_min_area_m2`` are interpolated (larger ones stay NaN: open
    water), then the surface is smoothed with ``trace_smoothing_m`` when that is > 0, and
    with ``trace_ground`` the objects standing on the ground are removed
    (:func:`remove_objects`, with the ``incision`` parameters: ground surface and threshold).

    Parameters
    ----------
    dem : ndarray (H, W) float32
        The DEM (m), NaN nodata.
    grid : GridSpec
    params : GullyParams
    workers : int
        FFT threads.
    incision : HeadDetectionParams, optional
        Ground surface and threshold of ``trace_ground``.
    hidden : ndarray bool (H, W), optional
        Crown mask (``gully.crowns``): there the surface is the harmonic interpolation of
        the hole-filled DEM around it (:func:`kitegully.gully.crowns.interpolate_under`),
        before the tracing smoothing.

    Returns
    -------
    z_heads : ndarray (H, W)
        The hole-filled DEM (heads are snapped and detected on it).
    z_trace : ndarray (H, W)
        The tracing surface (the input of the depression fill).
    n_holes : int
        Hole cells interpolated.

    Notes
    -----
    O(n log n) (the FFT smoothing); the interpolation of holes is global (a hole may
    cross any tile border), so a tiled site makes this surface in one job.
    """
    zi, n_holes = hole_filled(dem, grid, params)
    z_trace = zi
    if hidden is not None:
        z_trace, n_under = interpolate_under(zi, hidden)
        log.info("tracing surface: %d cells under crowns interpolated from the DSM around them", n_under)
    if params.trace_smoothing_m > 0:
        holes = ~np.isfinite(zi)
        z_trace = gaussian_smooth_fft(z_trace, params.trace_smoothing_m / grid.cell, truncate=params.truncate_sigmas,
                                      workers=workers)
        z_trace[holes] = np.nan
    if params.trace_ground:
        if incision is None:
            raise ValueError("gully.trace_ground needs the incision-map parameters (gully.automatic_heads)")
        z_trace, n_obj = remove_objects(zi, z_trace, grid.cell, incision, workers)
        log.info("tracing surface: %d cells (%.2f %%) stand on the ground (objects), traced on the ground surface",
                 n_obj, 100.0 * n_obj / max(1, int(np.isfinite(zi).sum())))
    return zi, z_trace, n_holes


def remove_objects(z: np.ndarray, z_trace: np.ndarray, cell_m: float, params: HeadDetectionParams,
                   workers: int = 1) -> tuple[np.ndarray, int]:
    """The tracing surface with objects standing on the ground replaced by the ground surface.

    A cell is an object where ``z_trace`` stands more than ``relief_k``·max(σ_z, ρ) above
    :func:`kitegully.gully.relief.ground_surface` of ``z`` (σ_z = ``dsm_sigma_z_m``, ρ the
    head-scale micro-relief of ``z``, :func:`kitegully.gully.relief.surface_roughness`): the
    same threshold above the ground as the detector's incision threshold below it (a step
    of 3 noise SDs, out of the furrows and crop rows). There the ground surface replaces it.
    O(n log n).

    Parameters
    ----------
    z : ndarray (H, W)
        The hole-filled DEM (m), NaN nodata.
    z_trace : ndarray (H, W)
        The tracing surface (m) on the same grid.
    cell_m : float
        Cell size (m).
    params : HeadDetectionParams
        ``scale_m``, ``slope_window_m``, ``relief_k`` and ``dsm_sigma_z_m`` are used.
    workers : int
        FFT threads.

    Returns
    -------
    z_trace : ndarray (H, W) float64
        The tracing surface, objects removed.
    n_objects : int
        Cells replaced.
    """
    valid = np.isfinite(z)
    ref = head_scale_ground(z, cell_m, params, workers)
    ground, rough = ref.ground, ref.rough
    thr = params.relief_k * max(params.dsm_sigma_z_m, rough)
    obj = valid & standing_above(z_trace, ground, thr)
    out = np.array(z_trace, dtype=np.float64, copy=True)
    out[obj] = ground[obj]
    log.info("object removal: threshold %.3f m (σ_z %.3f m, ρ %.3f m)", thr, params.dsm_sigma_z_m, rough)
    return out, int(obj.sum())

