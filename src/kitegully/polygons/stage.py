"""The whole polygon chain of Höfle et al. (2013, Fig. 4) as one function: :func:`measure_polygons`."""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from typing import Any, Mapping

import geopandas as gpd
import numpy as np
import pandas as pd
import shapely

from kitegully import InputError
from kitegully.config import config_section
from kitegully.io.raster import GridSpec
from kitegully.polygons.breaklines import CURVATURES, detect_breaklines, low_sides
from kitegully.polygons.conditioning import bank_held_depth, barrier_mask, fill_depth, gully_mask, polygons_from_labels, rasterize_lines
from kitegully.polygons.dem_prep import prepare_dem
from kitegully.polygons.morphometry import BRANCHES, NO_RIM, measure_sections
from kitegully.polygons.profiles import REFERENCES
from kitegully.polygons.skeleton import skeleton_paths
from kitegully.polygons.thalweg import thalweg_lines, topographic_convergence_index
from kitegully.polygons.transects import (clip_transects, make_transects, outlet_ends, station_floor, survey_edge_dams,
                                          transect_stations)

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class PolygonParams:
    """Method parameters: the ``polygons:`` config section without ``dem_file``, ``evaluation`` and ``figure``.

    Attributes
    ----------
    cell_m : float
        Cell of the stage's DEM (m) [P 0.5 m]; the input is resampled to it by minimum z.
    gap_neighbours : int
        Moving-plane fill: nearest valid cells per plane [P 10].
    gap_radius_m : float
        Moving-plane fill: search radius (m) [P 10 m].
    water_min_area_m2 : float or None
        Open water of the input DSM (:func:`kitegully.polygons.dem_prep.open_water`, in the
        curvature window): regions at least this large where most cells found no match stay
        empty [I]; None = off (a TLS or LiDAR DTM).
    window_cells : int
        Side of Wood's quadratic window (cells, odd) [P 9].
    curvature : str
        ``maximum``, ``plan`` or ``profile`` (:data:`kitegully.polygons.breaklines.CURVATURES`)
        [P says plan; I default maximum: plan curvature is zero across a straight edge].
    curvature_threshold_per_m : float
        Breakline threshold on the convexity (1/m) [P 0.2].
    breakline_min_length_m : float
        Breakline skeleton pieces shorter than this are dropped [I].
    upper_edges_only : bool
        Keep only convex cells with level ground on one side, not ridges (hedge and tree
        crowns of a DSM) [I] (:func:`kitegully.polygons.breaklines.upper_edge_mask`).
    edge_ground_m : float
        Make the upper-edge test (and the lower side of each breakline for ``below_rims``) on
        the ground under plants narrower than this (m): direction from the DEM's 2-D opening
        with a disc of this diameter, levels from the 1-D opening of the profile across the
        edge with a segment of this length [I]; 0 = on the DEM (a DTM). A shrub clump standing
        on a rim makes the DSM drop on both sides of it, a ridge, though the ground is an
        upper edge; the value is the widest clump to see through (the site's shrub-clump
        spacing, as ``ground_segment_m`` of the sections).
    tci_threshold : float
        Thalweg mask TCI > this [P 9, a in m²/m].
    mfd_exponent : float
        Slope exponent of the MFD partition [I 1.1, Freeman 1991].
    min_tan_slope : float
        Lower bound of tan β in the TCI [I].
    thalweg_min_length_m : float
        Shorter thalweg pieces are dropped [I].
    min_incision_m : float or None
        Thalweg cells must lie this far below the mean DEM within ± the transect half
        length [I]; None = no check.
    thalweg_closing_cells : int
        Closing of the TCI mask before the skeleton (cells) [I]; 1 = none.
    thalweg_follow_flow : bool
        Extend the thalweg mask down the D8 flow paths through incised cells, bridging up to
        ``thalweg_closing_cells`` (:func:`kitegully.polygons.thalweg.follow_flow`) [I]; needs
        ``min_incision_m``.
    thalweg_incision_ground_m : float or None
        Measure the incision on the ground surface, a grey opening of the DEM over a square
        of this side (m; the widest plant crown), against its own mean [I]; None = on the DEM.
    smooth_step_m : float
        Vertex spacing of the snakes smoothing of thalweg and medial axes (m) [I].
    snakes_alpha, snakes_beta : float
        Snakes weights [I 1, 1 as v.generalize].
    transect_spacing_m : float
        Transect spacing along the thalweg (m) [P 50].
    transect_half_length_m : float
        Transect length each side (m) [P 40].
    transect_max_drop_m : float or None
        Next transect where the thalweg has dropped this much (m) [I]; None = fixed spacing.
    transect_min_spacing_m : float
        Closest transect spacing (m) [I].
    transect_tangent_half_window_m : float
        Half length of the thalweg piece whose direction the transect is orthogonal to [I].
    survey_edge_dams : bool
        [I] Dam the survey's edge where a thalweg leaves the DEM
        (:func:`kitegully.polygons.transects.survey_edge_dams`).
    raise_m : float
        Height added to barrier cells (m) [P 10].
    grow_cells : int
        Barrier dilation (cells) [P 1].
    thresholds_m : tuple of float
        Fill-depth thresholds (m) [P 0.5 … 3.0].
    closing_cells : int
        Side of the square closing element (cells) [I 5 > the 3-cell barrier].
    bridge : str
        Cells the closing may add: ``all`` (plain closing [P]) or ``transects`` (only dam
        cells that are not breakline cells, so pools either side of a breakline stay apart [I]).
    min_area_m2 : float
        Smallest polygon (m²) [P 10].
    keep_on_thalweg : bool
        Keep only polygons touching the thalweg [I].
    terrain_held : bool or str
        The DEM with the dams alone (no breakline walls) must hold water at least t deep [I]
        (:func:`kitegully.polygons.conditioning.gully_mask`): ``True``/``"pools"`` = keep only
        pools with such a cell; ``"cells"`` = keep only such cells (water that only the raised
        breakline walls hold stands beyond the rims); ``False`` = no test.
    below_rims : bool
        Keep only pools on the lower side of the upper edges (breaklines) they touch [I].
    held_by_banks : bool
        Keep only polygons that hold water at least t deep somewhere with every dam raised
        only to the lower bank it spans (:func:`kitegully.polygons.conditioning.bank_held_depth`) [I].
    morph_threshold_m : float
        Fill-depth threshold of the polygons that get medial axes and sections [P 0.5].
    section_spacing_m : float
        Cross-section spacing (m) [P 10].
    reference : str
        Depth reference surface (:data:`kitegully.polygons.profiles.REFERENCES`) [I].
    branches : str
        Medial-axis branches that carry sections: ``all`` (every branch of the pruned medial
        network reaching half a spacing beyond its parent's edge [I]) or ``longest`` (the
        longest path only, METHODS 3.2 step 8) (:data:`kitegully.polygons.morphometry.BRANCHES`).
    rim_search_m : float
        Depth reference taken at the section ends prolonged to the nearest rim (breakline
        band) within this distance beyond the polygon edge (m) [I]; 0 = at the polygon edge.
    prolong_axes : bool
        Prolong the medial axes' free ends straight on to the polygon outline [I]: thinning
        stops an axis about a half width short of each end, so its slabs miss the ends.
    ground_segment_m : float
        Sections measured on their ground profile, a 1-D opening across the gully with this
        segment (m; the widest plant clump) [I]; 0 = on the DEM.
    ground_along_axis : bool
        With ``ground_segment_m``: each section's drape opened along the gully axis too, with
        the same segment, detrended by the floor's gradient
        (:func:`kitegully.polygons.profiles.drape_opened_along`) [I]: plants and the
        matching window only raise a DSM, and the clumps repeat along the strip as across it.
    bank_fit_m : float
        For ``reference`` ``banks`` / ``bank_lines``: length of ground beyond each reference end
        (m) that the pre-incision surface across the gully is fitted to
        (:func:`kitegully.polygons.profiles.bank_reference`) [I: one curvature window, the
        scale at which the stage already describes the surface around an edge].
    no_rim : str
        Where a section end that finds no rim within ``rim_search_m`` stays: ``outline`` (the
        polygon edge, t deep inside the gully) or ``highest_ground`` (the highest point of the
        ground profile within ``rim_search_m`` outside it) [I]
        (:func:`kitegully.polygons.morphometry.extend_to_rims`).
    """

    cell_m: float = 0.5
    gap_neighbours: int = 10
    gap_radius_m: float = 10.0
    water_min_area_m2: float | None = None
    window_cells: int = 9
    curvature: str = "maximum"
    curvature_threshold_per_m: float = 0.2
    breakline_min_length_m: float = 2.0
    upper_edges_only: bool = False
    edge_ground_m: float = 0.0
    tci_threshold: float = 9.0
    mfd_exponent: float = 1.1
    min_tan_slope: float = 0.001
    thalweg_min_length_m: float = 10.0
    min_incision_m: float | None = None
    thalweg_closing_cells: int = 1
    thalweg_follow_flow: bool = False
    thalweg_incision_ground_m: float | None = None
    smooth_step_m: float = 2.0
    snakes_alpha: float = 1.0
    snakes_beta: float = 1.0
    transect_spacing_m: float = 50.0
    transect_half_length_m: float = 40.0
    transect_max_drop_m: float | None = None
    transect_min_spacing_m: float = 3.0
    transect_tangent_half_window_m: float = 5.0
    survey_edge_dams: bool = False
    raise_m: float = 10.0
    grow_cells: int = 1
    thresholds_m: tuple = (0.5, 1.0, 1.5, 2.0, 2.5, 3.0)
    closing_cells: int = 5
    bridge: str = "all"
    min_area_m2: float = 10.0
    keep_on_thalweg: bool = True
    terrain_held: bool | str = False
    below_rims: bool = False
    held_by_banks: bool = False
    morph_threshold_m: float = 0.5
    section_spacing_m: float = 10.0
    reference: str = "lower_end"
    branches: str = "longest"
    rim_search_m: float = 0.0
    prolong_axes: bool = False
    ground_segment_m: float = 0.0
    ground_along_axis: bool = False
    bank_fit_m: float = 0.0
    no_rim: str = "outline"

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any]) -> "PolygonParams":
        """Build from the ``polygons:`` section (nested keys as in ``polygons.schema.yaml``)."""
        cfg = config_section(cfg, "polygons", ["cell_m", "gap_fill", "breaklines", "thalweg", "transects", "conditioning", "morphometry"],
                             optional=["dem_file", "dem_nodata", "evaluation", "figure_max_px"])
        g = config_section(cfg["gap_fill"], "polygons.gap_fill", ["neighbours", "radius_m"], optional=["water_min_area_m2"])
        b = config_section(cfg["breaklines"], "polygons.breaklines", ["window_cells", "curvature", "threshold_per_m", "min_length_m", "upper_edges_only"],
                           optional=["ground_segment_m"])
        t = config_section(cfg["thalweg"], "polygons.thalweg", ["tci_threshold", "mfd_exponent", "min_tan_slope", "min_length_m", "min_incision_m", "mask_closing_cells",
                                                                "smooth_step_m", "snakes_alpha", "snakes_beta"], optional=["follow_flow", "incision_ground_m"])
        tr = config_section(cfg["transects"], "polygons.transects", ["spacing_m", "half_length_m", "max_drop_m", "min_spacing_m", "tangent_half_window_m"],
                            optional=["survey_edge"])
        c = config_section(cfg["conditioning"], "polygons.conditioning", ["raise_m", "grow_cells", "thresholds_m", "closing_cells", "bridge",
                                                                          "min_area_m2", "keep_on_thalweg", "terrain_held", "below_rims"],
                           optional=["held_by_banks"])
        m = config_section(cfg["morphometry"], "polygons.morphometry", ["threshold_m", "spacing_m", "reference", "branches", "rim_search_m", "prolong_axes"],
                           optional=["ground_segment_m", "ground_along_axis", "bank_fit_m", "no_rim"])
        return cls(
            cell_m=cfg["cell_m"], gap_neighbours=g["neighbours"], gap_radius_m=g["radius_m"], water_min_area_m2=g.get("water_min_area_m2"),
            window_cells=b["window_cells"], curvature=b["curvature"], curvature_threshold_per_m=b["threshold_per_m"],
            breakline_min_length_m=b["min_length_m"], upper_edges_only=b["upper_edges_only"],
            edge_ground_m=float(b.get("ground_segment_m", 0.0)),
            tci_threshold=t["tci_threshold"], mfd_exponent=t["mfd_exponent"], min_tan_slope=t["min_tan_slope"],
            thalweg_min_length_m=t["min_length_m"], min_incision_m=t["min_incision_m"],
            thalweg_closing_cells=t["mask_closing_cells"], thalweg_follow_flow=bool(t.get("follow_flow", False)),
            thalweg_incision_ground_m=t.get("incision_ground_m"), smooth_step_m=t["smooth_step_m"], snakes_alpha=t["snakes_alpha"],
            snakes_beta=t["snakes_beta"],
            transect_spacing_m=tr["spacing_m"], transect_half_length_m=tr["half_length_m"], transect_max_drop_m=tr["max_drop_m"],
            transect_min_spacing_m=tr["min_spacing_m"], transect_tangent_half_window_m=tr["tangent_half_window_m"],
            survey_edge_dams=bool(tr.get("survey_edge", False)),
            raise_m=c["raise_m"], grow_cells=c["grow_cells"], thresholds_m=tuple(c["thresholds_m"]), closing_cells=c["closing_cells"],
            bridge=c["bridge"],
            min_area_m2=c["min_area_m2"], keep_on_thalweg=c["keep_on_thalweg"],
            terrain_held=c["terrain_held"], below_rims=c["below_rims"], held_by_banks=bool(c.get("held_by_banks", False)),
            morph_threshold_m=m["threshold_m"], section_spacing_m=m["spacing_m"], reference=m["reference"],
            branches=m["branches"], rim_search_m=float(m["rim_search_m"]), prolong_axes=bool(m["prolong_axes"]),
            ground_segment_m=float(m.get("ground_segment_m", 0.0)), ground_along_axis=bool(m.get("ground_along_axis", False)),
            bank_fit_m=float(m.get("bank_fit_m", 0.0)),
            no_rim=m.get("no_rim", "outline"),
        )

    def __post_init__(self) -> None:
        if self.curvature not in CURVATURES:
            raise InputError(f"polygons.breaklines.curvature: must be one of {CURVATURES}, got {self.curvature!r}")
        if self.reference not in REFERENCES:
            raise InputError(f"polygons.morphometry.reference: must be one of {REFERENCES}, got {self.reference!r}")
        if self.branches not in BRANCHES:
            raise InputError(f"polygons.morphometry.branches: must be one of {BRANCHES}, got {self.branches!r}")
        if self.no_rim not in NO_RIM:
            raise InputError(f"polygons.morphometry.no_rim: must be one of {NO_RIM}, got {self.no_rim!r}")
        if self.reference in ("banks", "bank_lines") and not self.bank_fit_m > 0:
            raise InputError(f"polygons.morphometry.bank_fit_m: reference {self.reference!r} needs a bank length > 0 (m), got {self.bank_fit_m}")
        if self.ground_segment_m < 0:
            raise InputError(f"polygons.morphometry.ground_segment_m: must be 0 or more, got {self.ground_segment_m}")
        if self.edge_ground_m < 0:
            raise InputError(f"polygons.breaklines.ground_segment_m: must be 0 or more, got {self.edge_ground_m}")
        if self.rim_search_m < 0:
            raise InputError(f"polygons.morphometry.rim_search_m: must be 0 or more, got {self.rim_search_m}")
        if self.window_cells < 3 or self.window_cells % 2 == 0:
            raise InputError(f"polygons.breaklines.window_cells: must be odd and at least 3, got {self.window_cells}")
        if self.terrain_held not in (False, True, "pools", "cells"):
            raise InputError(f"polygons.conditioning.terrain_held: must be false, true, 'pools' or 'cells', got {self.terrain_held!r}")
        if self.bridge not in ("all", "transects"):
            raise InputError(f"polygons.conditioning.bridge: must be 'all' or 'transects', got {self.bridge!r}")
        if self.morph_threshold_m not in self.thresholds_m:
            raise InputError(f"polygons.morphometry.threshold_m: {self.morph_threshold_m} is not one of conditioning.thresholds_m {list(self.thresholds_m)}")


@dataclass
class PolygonResult:
    """Products of :func:`measure_polygons` (rasters on the stage grid ``grid``)."""

    grid: GridSpec
    dem: np.ndarray
    curvature: np.ndarray
    breakline_cells: np.ndarray
    breaklines: gpd.GeoDataFrame
    tci: np.ndarray
    thalweg: gpd.GeoDataFrame
    transects: gpd.GeoDataFrame
    fill_depth: np.ndarray
    labels: dict[float, np.ndarray]
    polygons: dict[float, gpd.GeoDataFrame]
    axes: gpd.GeoDataFrame
    sections: gpd.GeoDataFrame
    morphometry: pd.DataFrame
    summary: pd.DataFrame
    timings_s: dict[str, float] = field(default_factory=dict)
    level: np.ndarray | None = None
    rims: np.ndarray | None = None


def measure_morphometry(labels: np.ndarray, polygons: gpd.GeoDataFrame, dem: np.ndarray, level: np.ndarray, rims: np.ndarray,
                        grid: GridSpec, params: PolygonParams) -> tuple[gpd.GeoDataFrame, gpd.GeoDataFrame, pd.DataFrame]:
    """Medial axes, cross-sections and morphometry of ``polygons`` (step 6 of :func:`measure_polygons`).

    Parameters
    ----------
    labels : ndarray int
        Labels of the polygons at ``params.morph_threshold_m`` (their ``polygon_id``).
    polygons : GeoDataFrame
        The polygons to measure (any subset of the labels: each is measured on its own).
    dem, level : ndarray
        Stage DEM and pool level (conditioned DEM + fill depth), m.
    rims : ndarray bool
        Breakline cells grown by ``params.grow_cells`` (the rim band).
    grid : GridSpec
        Grid of the arrays (the stage grid or a window of it).
    params : PolygonParams

    Returns
    -------
    axes, sections, morphometry
        As :func:`kitegully.polygons.morphometry.measure_sections`.
    """
    p = params
    return measure_sections(labels, polygons, dem, level, grid, p.section_spacing_m, p.reference, p.smooth_step_m, p.snakes_alpha,
                            p.snakes_beta, p.branches, rims, p.rim_search_m, p.prolong_axes, p.ground_segment_m,
                            p.bank_fit_m, p.no_rim, open_edges=p.survey_edge_dams,
                            edge_gap_cells=p.grow_cells + 1, ground_along_axis=p.ground_along_axis)


def morphometry_rows(axes: gpd.GeoDataFrame, sections: gpd.GeoDataFrame, morph: pd.DataFrame, params: PolygonParams) -> list[tuple]:
    """Rows of the summary table that describe the morphometry.

    Parameters
    ----------
    axes : GeoDataFrame
        Medial axes.
    sections : GeoDataFrame
        Cross-sections.
    morph : DataFrame
        Per-polygon morphometry with ``volume_m3``.
    params : PolygonParams
        Method parameters; the morphometry settings are listed.

    Returns
    -------
    list of tuple
        ``(label, value)`` rows.
    """
    p = params
    return [("medial axes", len(axes)), ("cross-sections", len(sections)), ("volume (m3)", round(float(morph["volume_m3"].sum()), 1)),
            ("depth reference", p.reference), ("section branches", p.branches),
            ("rim search beyond the polygon (m)", p.rim_search_m), ("axes prolonged to the outline", p.prolong_axes),
            ("ground segment across sections (m)", p.ground_segment_m),
            ("ground opened along the gully too", p.ground_along_axis and p.ground_segment_m > 0)]


def _lines_gdf(paths, grid: GridSpec) -> list[shapely.LineString]:
    xs, ys = grid.cell_centres()
    return [shapely.LineString(np.column_stack([xs[c], ys[r]])) for r, c in paths]


def measure_polygons(dem_in: np.ndarray, grid_in: GridSpec, params: PolygonParams, dem_name: str = "DEM",
                     morphometry: bool = True) -> PolygonResult:
    """Run the method: DEM prep, breaklines, thalweg, transects, conditioning, polygons, morphometry.

    Parameters
    ----------
    dem_in : ndarray (H, W)
        Input DSM/DTM (m), NaN nodata, any cell not coarser than ``params.cell_m``.
    grid_in : GridSpec
        Its grid.
    params : PolygonParams
        Method parameters.
    dem_name : str
        Name of the input for error messages.
    morphometry : bool
        Measure the polygons (step 6). False on tiled sites, whose tile jobs measure the
        polygons they own (:mod:`kitegully.polygons.tiles`): ``axes``, ``sections`` and
        ``morphometry`` are then empty and the summary has no morphometry rows.

    Returns
    -------
    PolygonResult

    Notes
    -----
    Dominated by the sort of the MFD routing and the two priority floods, O(n log n) in
    the n cells of the stage grid; ~1 M cells for a 600 × 400 m site at 0.5 m.

    Over ~80 lines on purpose: it is orchestration only, each block one call of a named
    phase function (tested on its own) plus that phase's timing in ``timings``.
    """
    p = params
    T: dict[str, float] = {}
    t0 = time.perf_counter()
    if grid_in.cell > p.cell_m * (1 + 1e-9):
        raise InputError(f"{dem_name}: cell {grid_in.cell} m is coarser than polygons.cell_m {p.cell_m} m")
    window_m = p.window_cells * p.cell_m
    dem, grid, prep = prepare_dem(dem_in, grid_in, p.cell_m, p.gap_neighbours, p.gap_radius_m, p.water_min_area_m2, window_m)
    if min(grid.width, grid.height) < 2 * p.window_cells:
        raise InputError(f"{dem_name}: the DEM at {grid.cell} m ({grid.height} x {grid.width} cells) is too small for the "
                         f"{p.window_cells} x {p.window_cells} curvature window ({window_m:.1f} m); it needs at least {2 * p.window_cells} cells a side")
    T["dem_prep_s"] = time.perf_counter() - t0

    t = time.perf_counter()
    bl_cells, curv = detect_breaklines(dem, grid.cell, p.window_cells, p.curvature_threshold_per_m, p.curvature, p.breakline_min_length_m,
                                         p.upper_edges_only, p.edge_ground_m)
    bl_lines = _lines_gdf(skeleton_paths(bl_cells, min_cells=2), grid)
    T["breaklines_s"] = time.perf_counter() - t

    t = time.perf_counter()
    tci, _ = topographic_convergence_index(dem, grid.cell, p.mfd_exponent, p.min_tan_slope)
    th_lines, th_cells = thalweg_lines(tci, grid, p.tci_threshold, p.thalweg_min_length_m, p.smooth_step_m, p.snakes_alpha, p.snakes_beta,
                                       dem, p.min_incision_m, 2.0 * p.transect_half_length_m,
                                       p.thalweg_closing_cells, p.thalweg_follow_flow, p.thalweg_incision_ground_m)
    T["thalweg_s"] = time.perf_counter() - t

    t = time.perf_counter()
    tr_all, line_id = [], []
    floor = station_floor(dem) if p.transect_max_drop_m is not None or p.survey_edge_dams else None
    for i, ln in enumerate(th_lines):
        st = transect_stations(ln, p.transect_spacing_m, dem, grid, p.transect_max_drop_m, p.transect_min_spacing_m, floor)
        tr = make_transects(ln, st, p.transect_half_length_m, p.transect_tangent_half_window_m)
        tr_all += tr
        line_id += [i] * len(tr)
    tr_clip, clipped = clip_transects(tr_all, bl_lines)
    edge_cells = np.zeros_like(bl_cells)
    if p.survey_edge_dams:
        edge_cells = survey_edge_dams(outlet_ends(th_lines, dem, grid, floor), dem, grid, p.transect_half_length_m, p.transect_half_length_m,
                                      barrier_mask(bl_cells, np.zeros_like(bl_cells), p.grow_cells))
        edge_lines = _lines_gdf(skeleton_paths(edge_cells, min_cells=2), grid)
        log.info("survey-edge dams: %d cells, %d lines", int(edge_cells.sum()), len(edge_lines))
        tr_clip += edge_lines
        clipped = np.concatenate([clipped, np.zeros(len(edge_lines), bool)])
        line_id += [-1] * len(edge_lines)
    T["transects_s"] = time.perf_counter() - t

    t = time.perf_counter()
    tr_cells = rasterize_lines(tr_clip, grid) | edge_cells
    barriers = barrier_mask(bl_cells, tr_cells, p.grow_cells)
    bl_band = barrier_mask(bl_cells, np.zeros_like(bl_cells), p.grow_cells) & ~bl_cells
    bridgeable = None
    if p.bridge == "transects":
        bridgeable = barrier_mask(tr_cells, np.zeros_like(tr_cells), p.grow_cells) & ~bl_band & ~bl_cells
    fd, cond = fill_depth(dem, barriers, p.raise_m)
    level = cond + fd
    rims = low_sides(dem, grid.cell, p.window_cells, bl_cells, p.edge_ground_m) if p.below_rims else None
    held = fill_depth(dem, barrier_mask(np.zeros_like(tr_cells), tr_cells, p.grow_cells), p.raise_m)[0] if p.terrain_held else None
    bank_held = bank_held_depth(tr_clip, dem, grid, p.grow_cells) if p.held_by_banks else None
    seeds = th_cells if p.keep_on_thalweg else None
    labels, polys = {}, {}
    for thr in p.thresholds_m:
        lab = gully_mask(fd, thr, p.closing_cells, p.min_area_m2, grid.cell, seeds, bridgeable, bl_band, p.grow_cells, held,
                         rims, held_cells=p.terrain_held == "cells", bank_held=bank_held)
        labels[thr] = lab
        polys[thr] = polygons_from_labels(lab, grid, thr, fd=fd)
        log.info("t = %.2f m: %d polygons, %.0f m2", thr, len(polys[thr]), polys[thr]["area_m2"].sum() if len(polys[thr]) else 0.0)
    T["conditioning_s"] = time.perf_counter() - t

    t = time.perf_counter()
    rim_band = barrier_mask(bl_cells, np.zeros_like(bl_cells), p.grow_cells)
    if morphometry:
        axes, sections, morph = measure_morphometry(labels[p.morph_threshold_m], polys[p.morph_threshold_m], dem, level, rim_band, grid, p)
    else:
        axes, sections, morph = measure_morphometry(np.zeros((1, 1), np.int32), polys[p.morph_threshold_m].iloc[:0], dem[:1, :1],
                                                    level[:1, :1], rim_band[:1, :1], grid, p)
    T["morphometry_s"] = time.perf_counter() - t
    T["total_s"] = time.perf_counter() - t0

    crs = grid.crs
    thalweg = gpd.GeoDataFrame({"line_id": range(len(th_lines)), "length_m": [l.length for l in th_lines]}, geometry=th_lines, crs=crs)
    transects = gpd.GeoDataFrame({"line_id": line_id, "clipped": clipped, "length_m": [l.length for l in tr_clip]},
                                 geometry=tr_clip if tr_clip else [], crs=crs)
    breaklines = gpd.GeoDataFrame({"length_m": [l.length for l in bl_lines]}, geometry=bl_lines if bl_lines else [], crs=crs)
    rows = [
        ("input DEM cell (m)", grid_in.cell),
        ("stage cell (m)", grid.cell),
        ("stage cells", grid.width * grid.height),
        ("empty cells after minimum-z resampling", prep["empty_cells"]),
        ("cells filled by moving planes", prep["filled_cells"]),
        ("curvature", f"{p.curvature}, {p.window_cells} x {p.window_cells} cells ({window_m:.1f} m), > {p.curvature_threshold_per_m} 1/m"),
        ("upper edges tested on", f"ground under plants < {p.edge_ground_m:g} m" if p.edge_ground_m > 0 else "the DEM"),
        ("breakline cells", int(bl_cells.sum())),
        ("breakline length (m)", round(float(breaklines["length_m"].sum()), 1)),
        ("thalweg lines", len(th_lines)),
        ("thalweg length (m)", round(float(thalweg["length_m"].sum()), 1)),
        ("transects", len(tr_clip)),
        ("transects clipped at breaklines", int(clipped.sum())),
        ("survey-edge dams (cells)", int(edge_cells.sum())),
        ("barrier cells", int(barriers.sum())),
    ]
    rows += [(f"polygons t = {thr} m (count / m2)", f"{len(polys[thr])} / {polys[thr]['area_m2'].sum():.1f}") for thr in p.thresholds_m]
    if morphometry:
        rows += morphometry_rows(axes, sections, morph, p)
    rows += [(f"time {k[:-2]} (s)", round(v, 2)) for k, v in T.items()]
    summary = pd.DataFrame(rows, columns=["quantity", "value"]).astype({"value": str})
    log.info("polygons done in %.1f s (%s)", T["total_s"], ", ".join(f"{k} {v:.1f}" for k, v in T.items()))
    return PolygonResult(grid, dem, curv, bl_cells, breaklines, tci, thalweg, transects, fd, labels, polys, axes, sections, morph, summary, T, level, rim_band)
