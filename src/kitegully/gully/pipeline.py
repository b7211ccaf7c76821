"""The whole gully-mapping chain of Feurer et al. (2018, Fig. 3) as one function."""

from __future__ import annotations

import logging
import os
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Callable

import geopandas as gpd
import numpy as np
import pandas as pd
from scipy.spatial import cKDTree

from kitegully.gully.crowns import hidden_reaches
from kitegully.gully.depth import depth_map
from kitegully.gully.heads import HeadDetectionParams, channel_entries, detect_heads
from kitegully.gully.relief import head_scale_ground, head_scale_relief, incision_map, visible_incisions
from kitegully.gully.inlets import edge_inlets, route_courses
from kitegully.gully.mapping import buffer_mask, final_map, gully_polygons
from kitegully.gully.network import GullyNetwork, network_lines, snap_heads, trace_network
from kitegully.gully.params import GullyParams
from kitegully.gully.patches import depth_patches
from kitegully.gully.surface import crowns_on, hole_filled, tracing_surface
from kitegully.io.raster import GridSpec, read_grid, read_raster
from kitegully.terrain.fill import priority_flood_fill
from kitegully.terrain.flats import flow_directions
from kitegully.terrain.flow import d8_directions
from kitegully.terrain.least_cost import least_cost_directions

log = logging.getLogger(__name__)


@dataclass
class GullyResult:
    """Products of :func:`map_gullies` (rasters on the DEM grid)."""

    smoothed: np.ndarray
    depth: np.ndarray
    patch_labels: np.ndarray
    patch_table: pd.DataFrame
    network: GullyNetwork
    gully: np.ndarray
    gully_whole_patches: np.ndarray
    polygons: gpd.GeoDataFrame
    lines: gpd.GeoDataFrame
    extracted_lines: gpd.GeoDataFrame
    heads_inside: np.ndarray
    n_hole_cells: int
    n_raised: int
    n_flat_routed: int
    timings_s: dict[str, float] = field(default_factory=dict)
    #: Flat indices of the automatically detected heads that were traced (empty unless ``auto_heads``
    #: was given; with given heads, only those farther than the snapping radius from all of them).
    auto_heads: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    #: Crown mask (``gully.crowns``; None when off) and the traced cells bridged under it (counted as mapped).
    crowns: np.ndarray | None = None
    bridged: np.ndarray | None = None
    #: Flat indices of the cells where a channel enters the DEM across its edge, traced after the heads
    #: (``edge_inlets``; empty when off).
    inlets: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    #: With given *and* automatic heads (``gully.heads: both``): the mapped network traced from the
    #: given heads and edge inlets alone, i.e. what ``gully.heads: digitised`` maps on the same DEM
    #: (the paper's procedure, scored beside the combined network). None otherwise.
    given_extracted_lines: gpd.GeoDataFrame | None = None


def map_gullies(
    dem: np.ndarray,
    grid: GridSpec,
    heads_x: np.ndarray,
    heads_y: np.ndarray,
    params: GullyParams,
    workers: int = 1,
    auto_heads: HeadDetectionParams | None = None,
    filled: np.ndarray | None = None,
    smoothed: np.ndarray | None = None,
    depth: np.ndarray | None = None,
    incision: HeadDetectionParams | None = None,
    ortho: np.ndarray | None = None,
    on_depth: Callable[[np.ndarray, np.ndarray], None] | None = None,
    crown_mask: np.ndarray | None = None,
    trace_surface: np.ndarray | str | os.PathLike | None = None,
) -> GullyResult:
    """Run steps a-m: depth map, patches, filled DEM, network from the heads, buffer ∩ patches.

    Parameters
    ----------
    dem : ndarray (H, W) float32
        The DEM (m), NaN nodata.
    grid : GridSpec
        Its grid.
    heads_x, heads_y : ndarray
        Gully head coordinates (site CRS, m).
    params : GullyParams
        Method parameters.
    workers : int
        Threads for the FFTs; with 2 or more, the tracing surface, depression fill and flow
        directions run in a second thread beside the depth map and patches (same results).
    auto_heads : HeadDetectionParams, optional
        Also detect heads from the DEM (:func:`kitegully.gully.heads.detect_heads`) and
        trace from them after the given heads (``gully.heads: automatic | both``).
    filled : ndarray (H, W), optional
        The ε = 0 priority-flood fill of :func:`tracing_surface`, made elsewhere (the
        tiled fill of a large site, :mod:`kitegully.terrain.tiled_fill`, equal bit for
        bit to the fill done here); only with ``flat_routing: resolve`` or ``least_cost``.
    smoothed, depth : ndarray (H, W) float32, optional
        The depth map (steps a-d) made elsewhere, both or neither: the merged depth
        tiles of a large site (:func:`kitegully.gully.depth.depth_map_tile`).
    incision : HeadDetectionParams, optional
        Parameters of the incision map for ``head_snap: incision`` (default: ``auto_heads``).
    ortho : ndarray (3, H, W), optional
        The orthophoto's R, G, B on the DEM grid (any unit; 0 = no data), for ``crowns``.
    on_depth : callable, optional
        Called as ``on_depth(smoothed, depth)`` once the depth map and patches are made,
        before waiting for the fill: with ``workers`` > 1 it runs beside the fill branch
        (e.g. the rule writes the two float rasters there, O(n) compression that would
        otherwise follow the fill on one core). It must not modify the arrays.
    crown_mask : ndarray bool (H, W), optional
        The crown mask of ``crowns`` made elsewhere (:func:`kitegully.gully.surface.crowns_on`; the trace-surface
        job of a large site, whose surface the tiled ``filled`` was made from); then
        ``ortho`` is not needed. A ``filled`` DEM with ``crowns`` needs it: the fill must
        have been made on the surface interpolated under the same crowns.
    trace_surface : ndarray (H, W), optional
        The tracing surface ``filled`` was made from (:func:`tracing_surface`, the
        trace-surface job of a large site); only with ``filled``. It is then not made
        again here (its smoothing, object removal and interpolation under crowns are
        whole-grid solves): only the hole-filled DEM the heads snap to is. A GeoTIFF path
        is read in the fill branch and dropped after it (at 80 M cells 0.32 GB that the
        rest of the map does not need; an array passed in stays alive with its caller).

    Returns
    -------
    GullyResult

    Notes
    -----
    O(n log n) for n cells. Peak memory about 8 bytes per cell for the float64 filled
    DEM plus 4 float32/int32 rasters (≈ 3 GB at 80 M cells), and the FFT work arrays
    (16 bytes per cell) during smoothing.
    """
    t: dict[str, float] = {}
    t0 = time.perf_counter()
    if (smoothed is None) != (depth is None):
        raise ValueError("give both the smoothed DEM and the depth map, or neither")
    if smoothed is not None and (smoothed.shape != dem.shape or depth.shape != dem.shape):
        raise ValueError(f"depth map has shape {depth.shape}, the DEM {dem.shape}")
    resolve = params.flat_routing == "resolve"
    least_cost = params.flat_routing == "least_cost"
    ip = incision if incision is not None else auto_heads
    if params.head_snap in ("incision", "relief", "posterior") and np.size(heads_x) and ip is None:
        raise ValueError(f"head_snap {params.head_snap!r} needs the incision-map parameters (gully.automatic_heads)")
    if params.edge_inlets and ip is None:
        raise ValueError("gully.edge_inlets needs the incision-map parameters (gully.automatic_heads)")
    if filled is not None:
        if not (resolve or least_cost):
            raise ValueError("a filled DEM from the tiled fill is the epsilon = 0 fill: it needs gully.flat_routing: "
                             "resolve or least_cost")
        if filled.shape != dem.shape:
            raise ValueError(f"filled DEM has shape {filled.shape}, the tracing surface {dem.shape}")
    trace_surface_file = isinstance(trace_surface, (str, os.PathLike))
    if trace_surface is not None:
        if filled is None:
            raise ValueError("a tracing surface made elsewhere is only used with the filled DEM made from it")
        ts_shape = read_grid(trace_surface).shape if trace_surface_file else np.shape(trace_surface)
        if ts_shape != dem.shape:
            raise ValueError(f"tracing surface has shape {ts_shape}, the DEM {dem.shape}")
    hidden = None
    if params.crowns.enabled and crown_mask is not None:
        if np.shape(crown_mask) != dem.shape:
            raise ValueError(f"crown mask has shape {np.shape(crown_mask)}, the DEM {dem.shape}")
        hidden = np.asarray(crown_mask, dtype=bool)
    elif params.crowns.enabled:
        if ortho is None or ip is None:
            raise ValueError("gully.crowns needs the orthophoto and the incision-map parameters (gully.automatic_heads)")
        if filled is not None:
            raise ValueError("gully.crowns changes the tracing surface: a filled DEM made elsewhere needs the crown mask "
                             "it was made with (crown_mask)")
        if np.shape(ortho)[1:] != dem.shape:
            raise ValueError(f"orthophoto has shape {np.shape(ortho)[1:]}, the DEM {dem.shape}")
        tc = time.perf_counter()
        hidden = crowns_on(dem, grid, params, ip, ortho, workers)
        t["crowns_s"] = time.perf_counter() - tc

    def flow_branch(given_filled: np.ndarray | None) -> tuple:
        """Steps f-i before the heads: tracing surface, fill (``given_filled`` if made elsewhere), flow directions."""
        tb = time.perf_counter()
        if trace_surface is None:
            z_heads, zi, n_holes = tracing_surface(dem, grid, params, 1, ip, hidden=hidden)
        else:
            (z_heads, n_holes), zi = hole_filled(dem, grid, params), (
                read_raster(trace_surface)[0] if trace_surface_file else trace_surface)
        if given_filled is None:
            fz, n_raised = priority_flood_fill(zi, params.fill_epsilon_m if params.flat_routing == "epsilon" else 0.0)
        else:
            fz = np.asarray(given_filled, dtype=np.float64)  # as priority_flood_fill returns it (same values)
            n_raised = int(np.count_nonzero(fz > zi))
            log.info("filled DEM: given (tiled priority flood), not filled here")
        dirs, n_flat, n_left = (None, 0, 0)
        if resolve:
            dirs, n_flat, n_left = flow_directions(fz)
        elif least_cost:
            dirs, n_flat = least_cost_directions(zi)  # n_flat: cells draining to a neighbour not below them
        del zi
        return z_heads, n_holes, fz, n_raised, dirs, n_flat, n_left, time.perf_counter() - tb

    # The fill and flat resolution (compiled, serial, without the GIL) run on one core while
    # the depth map's FFTs, the patch labelling and ``on_depth`` (the rule's writing of the
    # depth rasters) run beside them: both cores are busy.
    with ThreadPoolExecutor(max_workers=1) as pool:
        flow = pool.submit(flow_branch, filled) if workers > 1 else None
        if smoothed is None:
            smoothed, depth = depth_map(dem, grid.cell, params.sigma_m, params.truncate_sigmas, workers)
        t["smoothing_s"] = time.perf_counter() - t0
        log.info("depth map: σ = %.3g m, %d x %d cells, %.1f s", params.sigma_m, grid.height, grid.width, t["smoothing_s"])
        t0 = time.perf_counter()
        labels, table = depth_patches(depth, grid.cell, params.depth_threshold_m, params.min_patch_volume_m3,
                                      params.connectivity)
        t["patches_s"] = time.perf_counter() - t0
        log.info("patches: %d of %d kept (volume >= %.3g m3)", int(table["kept"].sum()), len(table),
                 params.min_patch_volume_m3)
        if on_depth is not None:
            t0 = time.perf_counter()
            on_depth(smoothed, depth)
            t["on_depth_s"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        z_heads, n_holes, filled, n_raised, dirs, n_flat, n_left, t_flow = (flow.result() if flow is not None
                                                                             else flow_branch(filled))
    # time spent waiting for the fill after the depth map and patches (its own time: t_flow)
    t["fill_s"] = time.perf_counter() - t0
    t["fill_branch_s"] = t_flow
    t0 = time.perf_counter()
    incised = relief = None
    relief_noise = None
    snap_on_relief = params.head_snap in ("relief", "posterior") and np.size(heads_x)
    # the detector's incision map starts from the same ground surface and roughness on the same cells (the DEM's
    # observed cells) when its scales are the snapping's: made once, handed to both (the same values bit for bit)
    shared_ground = None
    if snap_on_relief or params.edge_inlets:
        # on the observed cells only, as the detector's incision map: a head never snaps into an interpolated gap
        reference = head_scale_ground(dem, grid.cell, ip, workers)
        relief, rough = head_scale_relief(dem, grid.cell, ip, workers, reference=reference)
        relief_noise = max(float(ip.dsm_sigma_z_m), rough)
        if auto_heads is not None and (auto_heads.scale_m, auto_heads.slope_window_m) == (ip.scale_m, ip.slope_window_m):
            shared_ground = reference
        del reference
    incised_at_head_scale = None
    if params.edge_inlets:
        with np.errstate(invalid="ignore"):
            incised_at_head_scale = relief >= ip.relief_k * relief_noise
    if snap_on_relief:
        if params.head_snap == "posterior":
            log.info("head snapping: posterior of the digitising error (SD %.3g m) and the head-scale relief "
                     "(spread %.3g m = max(σ_z %.3g m, ρ %.3g m), k %.3g)", params.head_snap_radius_m / 3.0,
                     relief_noise, ip.dsm_sigma_z_m, rough, ip.relief_k)
    if params.head_snap == "incision" and np.size(heads_x):
        incised = visible_incisions(incision_map(z_heads, grid.cell, ip, workers, roughness=False)[0], grid.cell,
                                    ip.slope_window_m)
        incised = channel_entries(incised, dirs if dirs is not None else d8_directions(filled), grid.cell,
                                  ip.min_channel_length_m)
        log.info("head snapping: %d incised cells lead into a channel (candidates)", int(incised.sum()))
    inside_idx, inside = snap_heads(
        z_heads, grid, heads_x, heads_y, params.head_snap_radius_m, params.head_snap, depth=depth, patches=labels,
        smoothed=smoothed, incised=incised, relief=relief if snap_on_relief else None, relief_noise_m=relief_noise, relief_k=ip.relief_k if ip else 3.0,
    )
    del incised, relief
    t["snap_s"] = time.perf_counter() - t0
    log.info(
        "filled DEM (%s): %d hole cells interpolated (holes >= %s m2 kept as open water), %d cells raised, %d cells routed across flats "
        "(the flat mask) or out of depressions (least cost), "
        "%d cells left undrained, %.1f s",
        params.flat_routing, n_holes, params.water_min_area_m2, n_raised, n_flat, n_left, t_flow,
    )
    auto_idx = np.zeros(0, dtype=np.int64)
    given_idx = inside_idx
    if auto_heads is not None:
        t0 = time.perf_counter()
        auto_idx, _ = detect_heads(z_heads, filled, dirs if dirs is not None else d8_directions(filled), grid, auto_heads,
                                   workers, observed=np.isfinite(dem), reference=shared_ground)
        auto_idx = new_heads(auto_idx, grid, heads_x, heads_y, params.head_snap_radius_m)
        inside_idx = np.concatenate([inside_idx, auto_idx])
        t["auto_heads_s"] = time.perf_counter() - t0
    del z_heads, shared_ground
    inlet_idx = np.zeros(0, dtype=np.int64)
    if params.edge_inlets:
        t0 = time.perf_counter()
        # [I] 2σ: within it the depth map's Gaussian window is cut by the edge, so a patch there may be an edge effect
        inlet_idx, courses = edge_inlets(labels, depth, np.isfinite(filled), filled, dirs, grid.cell, 2.0 * params.sigma_m,
                                         incised=incised_at_head_scale)
        if courses:  # across the edge band the paths follow the inlets' courses, then the DEM
            dirs = route_courses(d8_directions(filled) if dirs is None else dirs, courses)
        inside_idx = np.concatenate([inside_idx, inlet_idx])
        t["inlets_s"] = time.perf_counter() - t0
        log.info("edge inlets: %d channels enter the DEM across its edge (depth patches crossing the %.3g m edge band "
                 "and %.3g m beyond, half of each incised at the head scale), %.1f s", inlet_idx.size, 2.0 * params.sigma_m,
                 2.0 * params.sigma_m, t["inlets_s"])
    del incised_at_head_scale

    t0 = time.perf_counter()
    network = trace_network(filled, inside_idx, dirs)
    # gully.heads: both also maps the given heads' network alone (the paper's procedure): the same
    # fill, directions and snapped heads, so it is exactly what gully.heads: digitised would trace
    separate = auto_heads is not None and np.size(heads_x) > 0
    given_network = (trace_network(filled, np.concatenate([given_idx, inlet_idx]), dirs)
                     if separate and auto_idx.size else None)
    del filled, dirs
    t["trace_s"] = time.perf_counter() - t0
    log.info(
        "network: %d of %d heads on the DEM, %d cells, %d segments, %d paths to an outlet, %d in a pit",
        int(inside.sum()), inside.size, network.cells.size, network.n_segments,
        network.n_paths_to_outlet(), network.n_paths_not_at_outlet(),
    )

    t0 = time.perf_counter()
    gully, whole, bridged, extracted = mapped_network(network, labels, grid, params, hidden)
    polygons = gully_polygons(gully, depth, grid, params.connectivity)
    lines = network_lines(network, grid)
    if hidden is not None:
        log.info("crowns: %d traced cells under crowns, %d of them bridged (hidden reaches <= %s m)",
                 int(hidden.ravel()[network.cells].sum()), int(bridged.sum()), params.crowns.bridge_max_m)
    given_extracted = extracted if separate and given_network is None else None  # no automatic head was new
    if given_network is not None:
        given_extracted = mapped_network(given_network, labels, grid, params, hidden, whole=False)[3]
        log.info("given heads alone (gully.heads: digitised on this DEM): %.0f m inside the map",
                 given_extracted["length_m"].sum())
    t["map_s"] = time.perf_counter() - t0
    log.info(
        "gully map: %d gullies, %.0f m2, %.0f m3; network %.0f m traced, %.0f m inside the map",
        len(polygons), polygons["area_m2"].sum(), polygons["volume_m3"].sum(),
        lines["length_m"].sum(), extracted["length_m"].sum(),
    )
    return GullyResult(
        smoothed, depth, labels, table, network, gully, whole, polygons, lines, extracted, inside, n_holes, n_raised,
        n_flat, t, auto_idx, hidden, bridged, inlet_idx, given_extracted,
    )


def mapped_network(network: GullyNetwork, labels: np.ndarray, grid: GridSpec, params: GullyParams,
                   hidden: np.ndarray | None = None, whole: bool = True,
                   ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None, gpd.GeoDataFrame]:
    """Steps l-m: the gully map (depth patches inside the network's buffer) and the mapped network.

    Parameters
    ----------
    network : GullyNetwork
        The traced network.
    labels : ndarray (H, W) int
        Depth-patch labels (0: no patch).
    grid : GridSpec
    params : GullyParams
        ``buffer_m`` and ``crowns.bridge_max_m`` are read.
    hidden : ndarray bool (H, W), optional
        Crown mask (``gully.crowns``): traced reaches hidden under it are bridged.
    whole : bool
        Also make the whole-patch variant of the map.

    Returns
    -------
    gully : ndarray bool (H, W)
        The gully map.
    gully_whole : ndarray bool (H, W) or None
        Whole depth patches touched by the buffer (None unless ``whole``).
    bridged : ndarray bool (H, W) or None
        Traced cells bridged under crowns (None without ``hidden``).
    lines : geopandas.GeoDataFrame
        The network's lines where they lie in the map (or are bridged).
    """
    buf = buffer_mask(network.mask(), grid.cell, params.buffer_m)
    gully = final_map(labels, buf)
    gully_whole = final_map(labels, buf, whole_patches=True) if whole else None
    del buf
    bridged = None
    if hidden is not None:
        bridged = hidden_reaches(network.cells, network.pos_down, gully, hidden, grid.cell, params.crowns.bridge_max_m)
    lines = network_lines(network, grid, keep=gully if bridged is None else gully | bridged)
    return gully, gully_whole, bridged, lines


def new_heads(auto_idx: np.ndarray, grid: GridSpec, heads_x: np.ndarray, heads_y: np.ndarray,
              radius_m: float) -> np.ndarray:
    """Automatic heads (flat cell indices) farther than ``radius_m`` from every given head.

    ``gully.heads: both`` is the operator accepting a detector's suggestions: [I] an
    automatic head within the snapping radius of a digitised head is the incision that
    digitised head snaps to (the same head, found twice), so only those beyond it are new
    heads the operator did not digitise. With no given heads every automatic head is kept.
    O((k + m) log m) for k automatic and m given heads.

    Parameters
    ----------
    auto_idx : ndarray int64
        Flat cell indices of the automatic heads.
    grid : GridSpec
        Their grid.
    heads_x, heads_y : ndarray
        Map coordinates of the given heads (m).
    radius_m : float
        Automatic heads this close to a given head or closer are dropped (m).

    Returns
    -------
    ndarray int64
        The kept automatic heads, in their order.
    """
    auto_idx = np.asarray(auto_idx, dtype=np.int64)
    if auto_idx.size == 0 or np.size(heads_x) == 0:
        return auto_idx
    xs, ys = grid.cell_centres()
    r, c = np.divmod(auto_idx, grid.width)
    d, _ = cKDTree(np.column_stack([heads_x, heads_y])).query(np.column_stack([xs[c], ys[r]]), k=1)
    keep = d > radius_m
    log.info("automatic heads: %d of %d farther than %.3g m from every digitised head (kept)", int(keep.sum()),
             auto_idx.size, radius_m)
    return auto_idx[keep]


def map_raster(mask: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """A gully mask as written to ``gully_map.tif``: uint8 1 gully, 0 not, 255 off the DEM."""
    m = mask.astype(np.uint8)
    m[~valid] = 255
    return m


def gully_summary(res: GullyResult, grid: GridSpec, params: GullyParams, dem_source: str, n_heads: int,
                  heads: str = "digitised") -> pd.DataFrame:
    """The ``gully_summary.csv`` table of a :func:`map_gullies` run: ``quantity, value`` (text).

    Parameters
    ----------
    res : GullyResult
        The mapping run.
    grid : GridSpec
        Grid of the mapping DEM.
    params : GullyParams
        Its parameters (the settings worth reporting beside the numbers).
    dem_source : str
        ``gully.dem``: which DEM was mapped.
    n_heads : int
        Number of digitised gully heads given.
    heads : str
        ``gully.heads``: where the heads came from (digitised, automatic or both).
    """
    rows = [
        ("DEM source", dem_source),
        ("DEM cells", grid.width * grid.height),
        ("cell size (m)", grid.cell),
        ("head source (gully.heads)", heads),
        ("gully heads", int(n_heads)),
        ("automatic heads", int(res.auto_heads.size)),
        ("channels entering across the DEM edge (edge_inlets)", int(res.inlets.size)),
        ("heads on the DEM", int(res.heads_inside.sum())),
        ("head snapping", f"{params.head_snap} cell within {params.head_snap_radius_m} m"),
        ("tracing DEM smoothing sigma (m)", params.trace_smoothing_m),
        ("paths ending at an outlet", res.network.n_paths_to_outlet()),
        ("paths ending in a pit", res.network.n_paths_not_at_outlet()),
        ("traced network length (m)", round(float(res.lines["length_m"].sum()), 1)),
        ("mapped network length (m)", round(float(res.extracted_lines["length_m"].sum()), 1)),
        ("network segments", res.network.n_segments),
        ("max Strahler order", int(res.network.seg_order.max()) if res.network.n_segments else 0),
        ("depth patches kept", int(res.patch_table["kept"].sum())),
        ("gullies (polygons)", len(res.polygons)),
        ("gully area (m2)", round(float(res.polygons["area_m2"].sum()), 1)),
        ("gully volume (m3)", round(float(res.polygons["volume_m3"].sum()), 1)),
        ("gully area, whole-patch variant (m2)", round(float(res.gully_whole_patches.sum()) * grid.cell**2, 1)),
        ("interpolated hole cells", res.n_hole_cells),
        ("holes kept as open water from (m2)", params.water_min_area_m2),
        ("cells raised by filling", res.n_raised),
        ("flow routing across flats", params.flat_routing),
        ("flat cells routed by the flat mask" if params.flat_routing != "least_cost"
         else "cells breached (draining to a neighbour not below them)", res.n_flat_routed),
    ] + [(f"time {k[:-2]} (s)", round(v, 2)) for k, v in res.timings_s.items()]
    return pd.DataFrame(rows, columns=["quantity", "value"]).astype({"value": str})
