"""Medial axes and cross-sections of the gully polygons (Höfle et al. 2013 sect. 4.2-4.3, Figs 10-11).

Per polygon: grassfire thinning of its raster to a one-cell skeleton, and either its longest
path (the paper's pruned medial axis, ``branches="longest"``) or its pruned medial network
(``"all"``: the longest path, then every branch reaching half a spacing beyond its parent's
edge, :func:`kitegully.polygons.skeleton.branch_paths`), smoothed with snakes and optionally
prolonged at their free ends to the outline (:func:`prolong_to_outline`). Cross-sections
orthogonal to each branch, one at the middle of each of ``n = round(L' / spacing)`` equal
slabs of its measured length ``L'`` (the branch less its part inside the parent), clipped to
the polygon and draped on the DEM:

- width = clipped length (m);
- depth = max(z_ref − z) (m);
- area = ∫ max(z_ref − z, 0) ds (m²), trapezoidal at half-cell steps;
- volume = Σ area · L' / n (m³).

Reference surface ``z_ref`` (:data:`REFERENCES`): ``lower_end`` = elevation of the lower
end of the section, level across ([I] METHODS.md 3.2 step 9); ``line`` = straight line
between the two ends; ``spill`` = the sink-fill level of the conditioned DEM (the spill
surface of the pool the section lies in); ``banks`` = one parabola fitted to the ground over
``bank_fit_m`` beyond both reference ends, ``bank_lines`` = a line fitted to each of them, both
extended across and blended (:func:`bank_reference`: the pre-incision surface of a gully cut
into a hollow or a valley floor, which the straight line between the rims cuts across).
With rim cells given, the ends are first
prolonged outwards to the rim (:func:`extend_to_rims`), so the reference stands on the
upper edges rather than on the pool's outline. With a ground segment length ``g`` > 0 (a DSM
with low vegetation on the rims), the profile is first replaced by its ground
(:func:`ground_profile`: a 1-D grey opening with a segment of length ``g`` along the section,
prolonged by ``g`` beyond both reference ends so that the field beside each rim is seen).

The medial axes are :mod:`kitegully.polygons.medial`'s, the draped profiles and the reference
surfaces :mod:`kitegully.polygons.profiles`'; this module cuts and measures the sections
(:func:`measure_sections`).
"""

from __future__ import annotations

import logging

import geopandas as gpd
import numpy as np
import pandas as pd
import scipy.ndimage as ndi
import shapely
import shapely.ops
from scipy.ndimage import map_coordinates

from kitegully.io.raster import GridSpec
from kitegully.polygons.medial import (clip_to_extent, medial_axis, medial_network, open_at_edges, prolong_to_outline,
                                       without_holes)
from kitegully.polygons.profiles import (END_TOL, REFERENCES, axis_gradient, bank_reference, drape, drape_opened_along,
                                         ground_profile, section_profile)

log = logging.getLogger(__name__)

#: Where a section end without a rim stays (``polygons.morphometry.no_rim``).
NO_RIM = ("outline", "highest_ground")
#: Which medial-axis branches carry sections (``polygons.morphometry.branches``).
BRANCHES = ("all", "longest")


def _section_piece(poly, px: float, py: float, nx: float, ny: float, half: float):
    line = shapely.LineString([(px - half * nx, py - half * ny), (px + half * nx, py + half * ny)])
    inter = line.intersection(poly)
    parts = [g for g in getattr(inter, "geoms", [inter]) if g.geom_type == "LineString" and not g.is_empty]
    if not parts:
        return None
    pt = shapely.Point(px, py)
    return min(parts, key=lambda g: g.distance(pt))


def _rim_offset(end_xy: np.ndarray, out_dir: np.ndarray, rims: np.ndarray, grid: GridSpec, search: float, step: float) -> float:
    """Distance (m) from a section end outwards to the rim within ``search``; 0 if none.

    The rim is the middle of the first run of rim cells the prolonged section crosses: the
    rim cells are the breakline skeleton dilated by the barrier growth, so their middle is
    the breakline itself (the upper edge). The highest point of the run would be biased
    upwards by the DSM's noise and by the surface rising beyond the edge.
    """
    k = np.arange(0, int(np.floor(search / step)) + 1)
    x = end_xy[0] + out_dir[0] * k * step
    y = end_xy[1] + out_dir[1] * k * step
    r, c = grid.rowcol(x, y)
    r = np.round(np.asarray(r)).astype(int)
    c = np.round(np.asarray(c)).astype(int)
    ok = (r >= 0) & (r < rims.shape[0]) & (c >= 0) & (c < rims.shape[1])
    hit = np.zeros(k.size, bool)
    hit[ok] = rims[r[ok], c[ok]]
    if not hit.any():
        return 0.0
    i0 = int(np.argmax(hit))
    i1 = i0 + (int(np.argmin(hit[i0:])) if not hit[i0:].all() else hit.size - i0)  # end of the first run
    return float(0.5 * (k[i0] + k[i1 - 1]) * step)


def _highest_ground_offset(end_xy: np.ndarray, out_dir: np.ndarray, dem: np.ndarray, grid: GridSpec, search: float, step: float,
                           segment_m: float) -> float:
    """Distance (m) from a section end outwards to the highest point of the ground profile within ``search``.

    The profile is draped every ``step`` from one segment inside the end to one segment beyond
    ``search`` and opened with ``segment_m`` (:func:`ground_profile`), so a plant clump is not
    taken for the upper edge. O(search / step).
    """
    n_seg = int(np.ceil(segment_m / step)) if segment_m > 0 else 0
    k = np.arange(-n_seg, int(np.floor(search / step)) + n_seg + 1)
    x = end_xy[0] + out_dir[0] * k * step
    y = end_xy[1] + out_dir[1] * k * step
    r, c = grid.rowcol(x, y)
    z = map_coordinates(dem, [np.asarray(r, float), np.asarray(c, float)], order=1, mode="nearest")
    g = ground_profile(z, step, segment_m) if segment_m > 0 else z
    sel = (k >= 0) & (k * step <= search + 1e-9) & np.isfinite(g)
    if not sel.any():
        return 0.0
    return float(k[sel][int(np.argmax(g[sel]))] * step)


def extend_to_rims(piece: shapely.LineString, rims: np.ndarray, grid: GridSpec, search: float, dem: np.ndarray | None = None,
                   segment_m: float = 0.0) -> tuple[shapely.LineString, float]:
    """The clipped section prolonged at each end to the nearest rim within ``search`` m (:func:`_rim_offset`).

    With ``dem`` given, an end that finds no rim cell within ``search`` is prolonged instead to
    the highest point of the ground profile within ``search`` (:func:`_highest_ground_offset`):
    the polygon's outline lies t deep inside the gully, and where the breakline test marked no
    upper edge the wall still rises to one; where the field beyond keeps rising the end goes the
    whole ``search`` (with ``reference="banks"`` that field lies on the fitted bank surface and
    adds no depth or area).

    Returns the prolonged line and the offset (m) of the clipped section's start along it.

    Parameters
    ----------
    piece : LineString
        The section clipped to the polygon.
    rims : ndarray (H, W) bool
        Rim cells.
    grid : GridSpec
        Grid of ``rims`` and ``dem``.
    search : float
        Farthest prolongation of each end (m).
    dem : ndarray (H, W) or None
        DEM (m) for ends without a rim; None = such ends stay.
    segment_m : float
        Opening segment of the ground profile searched with ``dem`` (m); 0 = the DEM as it is.

    Returns
    -------
    line : LineString
        The prolonged section.
    offset : float
        Distance from its start to the clipped section's start (m).
    """
    a, b = np.asarray(piece.coords[0])[:2], np.asarray(piece.coords[-1])[:2]
    L = float(np.hypot(*(b - a)))
    if L == 0:
        return piece, 0.0
    u = (b - a) / L
    step = 0.5 * grid.cell
    oa = _rim_offset(a, -u, rims, grid, search, step)
    ob = _rim_offset(b, u, rims, grid, search, step)
    if dem is not None:
        if oa == 0.0:
            oa = _highest_ground_offset(a, -u, dem, grid, search, step, segment_m)
        if ob == 0.0:
            ob = _highest_ground_offset(b, u, dem, grid, search, step, segment_m)
    return shapely.LineString([a - oa * u, b + ob * u]), oa


def _drape_section(line: shapely.LineString, dem: np.ndarray, grid: GridSpec, step: float, segment_m: float,
                   along: tuple[np.ndarray, float] | None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`drape`, or with ``along`` = (axis direction, gradient) :func:`drape_opened_along`."""
    if along is None:
        return drape(line, dem, grid, step)
    return drape_opened_along(line, dem, grid, step, along[0], along[1], segment_m)


def _ground_drape(line: shapely.LineString, dem: np.ndarray, grid: GridSpec, step: float, segment_m: float,
                  along: tuple[np.ndarray, float] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(s, ground z) along ``line``: drape the line prolonged by ``segment_m`` at both ends, open it, cut back.

    ``along`` = (unit axis direction, floor gradient): the drape is opened along the axis first
    (:func:`drape_opened_along`).
    """
    a, b = np.asarray(line.coords[0])[:2], np.asarray(line.coords[-1])[:2]
    L = float(np.hypot(*(b - a)))
    if L == 0:
        s, _, _, z = drape(line, dem, grid, step)
        return s, z
    u = (b - a) / L
    n_out = int(np.ceil(segment_m / step))
    ext = shapely.LineString([a - n_out * step * u, b + n_out * step * u])
    s_all, _, _, z_all = _drape_section(ext, dem, grid, step, segment_m, along)
    g = ground_profile(z_all, float(s_all[1] - s_all[0]) if s_all.size > 1 else step, segment_m)
    s = np.linspace(0.0, L, max(int(np.ceil(L / step)), 1) + 1)
    return s, np.interp(s + n_out * step, s_all, g)


def _bank_drape(line: shapely.LineString, dem: np.ndarray, grid: GridSpec, step: float, segment_m: float,
                fit_m: float, model: str = "quadratic", along: tuple[np.ndarray, float] | None = None
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(s, z, z_ref) along ``line`` with the :func:`bank_reference` of its ends.

    The line is draped prolonged by ``fit_m`` (+ ``segment_m`` for the ground opening, which is
    unreliable within one segment of the prolonged ends) at both ends, opened
    (:func:`ground_profile`), and the banks fitted on the prolonged parts. ``along`` = (unit
    axis direction, floor gradient): the drape is opened along the axis first
    (:func:`drape_opened_along`).
    """
    a, b = np.asarray(line.coords[0])[:2], np.asarray(line.coords[-1])[:2]
    L = float(np.hypot(*(b - a)))
    n = max(int(np.ceil(L / step)), 1)
    s = np.linspace(0.0, L, n + 1)
    if L == 0:
        _, _, _, z = drape(line, dem, grid, step)
        return s, z, z.copy()
    u = (b - a) / L
    out = int(np.ceil((fit_m + segment_m) / step)) * step
    ext = shapely.LineString([a - out * u, b + out * u])
    s_all, _, _, z_all = _drape_section(ext, dem, grid, step, segment_m, along)
    if segment_m > 0:
        z_all = ground_profile(z_all, float(s_all[1] - s_all[0]) if s_all.size > 1 else step, segment_m)
    s_all = s_all - out
    z = np.interp(s, s_all, z_all)
    # the banks: samples beyond the ends by more than bank_reference's own tolerance, so that exactly
    # the n + 1 samples of s count as the section (a sample of the prolonged drape that rounding puts
    # within 1e-9 m of an end was counted twice: a reference one sample longer than the section)
    left, right = s_all < -END_TOL, s_all > L + END_TOL
    s_b = np.concatenate([s_all[left], s, s_all[right]])
    z_b = np.concatenate([z_all[left], z, z_all[right]])
    return s, z, bank_reference(s_b, z_b, L, fit_m, model)


def measure_sections(
    labels: np.ndarray,
    polygons: gpd.GeoDataFrame,
    dem: np.ndarray,
    level: np.ndarray,
    grid: GridSpec,
    spacing: float,
    reference: str,
    smooth_step: float,
    alpha: float,
    beta: float,
    branches: str = "all",
    rims: np.ndarray | None = None,
    rim_search_m: float = 0.0,
    prolong: bool = False,
    ground_segment_m: float = 0.0,
    bank_fit_m: float = 0.0,
    no_rim: str = "outline",
    open_edges: bool = False,
    edge_gap_cells: int = 0,
    ground_along_axis: bool = False,
) -> tuple[gpd.GeoDataFrame, gpd.GeoDataFrame, pd.DataFrame]:
    """Medial axes, cross-sections and per-polygon morphometry.

    Parameters
    ----------
    labels : ndarray int
        Polygon labels (0 = none), the ``polygon_id`` of ``polygons``.
    polygons : GeoDataFrame
        The vectorised polygons (``polygon_id``, geometry).
    dem : ndarray
        DEM the sections are draped on (m).
    level : ndarray
        Pool level = sink-filled conditioned DEM (m), for ``reference="spill"``.
    grid : GridSpec
    spacing : float
        Nominal cross-section spacing (m); 10 m in the paper.
    reference : str
        Depth reference (:data:`REFERENCES`).
    smooth_step, alpha, beta : float
        Vertex spacing (m) and snakes weights of the axis smoothing.
    branches : str
        ``longest``: sections along the longest path only (the paper's pruned medial axis);
        ``all``: along every branch of the pruned medial network that reaches at least half
        a spacing beyond its parent's edge (one slab of its own; :func:`medial_network`).
    rims : ndarray bool or None
        Rim (breakline) cells; when given, the depth reference is taken at the section's
        ends prolonged outwards to the nearest rim cell within ``rim_search_m`` (width
        stays the clipped length).
    rim_search_m : float
        Search distance beyond the polygon edge for the rim (m).
    prolong : bool
        Prolong the axes' free ends to the outline (:func:`prolong_to_outline`), so that the
        slabs cover the polygon's ends too.
    ground_segment_m : float
        Depth and area are measured on the section's ground profile (:func:`ground_profile`
        with this segment, m), draped over the reference line prolonged by the segment at both
        ends; 0 = on the DEM as it is.
    bank_fit_m : float
        For ``reference="banks"`` / ``"bank_lines"``: length of ground fitted beyond each
        reference end (m) (:func:`bank_reference`); must be > 0 then.
    no_rim : str
        Where a section end that finds no rim within ``rim_search_m`` stays (:data:`NO_RIM`):
        ``outline`` = on the polygon outline; ``highest_ground`` = at the highest point of the
        ground profile within ``rim_search_m`` outside it (:func:`extend_to_rims`).
    open_edges : bool
        A polygon the DEM's edge cuts is thinned as if it went on across the edge
        (:func:`open_at_edges`), so that its axis runs out through the edge instead of
        forking into the corners of the cut (surveys that end inside a gully).
    edge_gap_cells : int
        With ``open_edges``: a polygon this close to the DEM's edge (cells) reaches it.
    ground_along_axis : bool
        With ``ground_segment_m`` > 0: each section's drape is opened along the gully axis too
        (:func:`drape_opened_along`, detrended by :func:`axis_gradient`) before the opening
        across it: the ground between plant clumps along the strip.

    Returns
    -------
    axes : GeoDataFrame
        ``polygon_id, branch, length_m, trim_m`` and the medial axis (branch 0 = longest path).
    sections : GeoDataFrame
        ``polygon_id, branch, station_m, width_m, depth_m, area_m2, slab_m, reference_length_m``
        (length of the section between the points its depth reference stands on: the rims
        when found, else the clipped ends) and the clipped section draped on the DEM (3-D).
    morph : DataFrame
        Per polygon: area, axis length (all branches), sections, mean/max width and depth, volume.

    Notes
    -----
    O(Σ bounding-box cells) for the thinning plus O(sections · section length / cell).
    Slabs: a branch of length L with trim t gets n = round((L − t) / spacing) sections
    (at least one), each standing for a slab of (L − t) / n, so the slabs of all branches
    tile the network once and volume = Σ area · slab.
    """
    if reference not in REFERENCES:
        raise ValueError(f"reference must be one of {REFERENCES}, got {reference!r}")
    if branches not in BRANCHES:
        raise ValueError(f"branches must be one of {BRANCHES}, got {branches!r}")
    if no_rim not in NO_RIM:
        raise ValueError(f"no_rim must be one of {NO_RIM}, got {no_rim!r}")
    if reference in ("banks", "bank_lines") and bank_fit_m <= 0:
        raise ValueError(f"reference {reference!r} needs bank_fit_m > 0")
    dem64 = np.asarray(dem, np.float64)
    lev64 = np.asarray(level, np.float64)
    objs = ndi.find_objects(labels)
    geom_of = dict(zip(polygons["polygon_id"], polygons.geometry))
    ax_rec, sec_rec, morph = [], [], []
    step = 0.5 * grid.cell
    for pid, sl in enumerate(objs, start=1):
        if sl is None or pid not in geom_of:
            continue
        poly = without_holes(geom_of[pid])
        r0, c0 = max(sl[0].start - 1, 0), max(sl[1].start - 1, 0)
        r1, c1 = min(sl[0].stop + 1, labels.shape[0]), min(sl[1].stop + 1, labels.shape[1])
        own = labels[r0:r1, c0:c1] == pid
        sub, top, left = open_at_edges(own, r0, c0, labels.shape, edge_gap_cells) if open_edges else (own, r0, c0)
        if branches == "all":
            net = medial_network(sub, grid, top, left, smooth_step, alpha, beta, 0.5 * spacing)
        else:
            axis = medial_axis(sub, grid, top, left, smooth_step, alpha, beta)
            net = [(axis, 0.0)] if axis is not None and axis.length > 0 else []
        if sub is not own:  # continued across the edge: cut the axes back to the DEM
            net = [(a, t) for a, t in ((clip_to_extent(a, grid), t) for a, t in net) if a is not None]
        row = {"polygon_id": pid, "area_m2": poly.area, "length_m": 0.0, "n_sections": 0, "mean_width_m": np.nan,
               "max_width_m": np.nan, "mean_depth_m": np.nan, "max_depth_m": np.nan, "volume_m3": 0.0}
        half = float(np.hypot(r1 - r0, c1 - c0)) * grid.cell + 1.0
        ws, ds, vol, total_len = [], [], 0.0, 0.0
        for bi, (axis, trim) in enumerate(net):
            if prolong:
                axis = prolong_to_outline(axis, poly, start=bi == 0, end=True, look_m=2.0 * smooth_step)
            L = axis.length
            usable = L - trim
            if usable < 0.5 * spacing and bi > 0:
                continue
            usable = max(usable, 1e-9)
            total_len += usable
            ax_rec.append({"polygon_id": pid, "branch": bi, "length_m": L, "trim_m": trim, "geometry": axis})
            n = max(1, int(round(usable / spacing)))
            slab = usable / n
            for k in range(n):
                s0 = trim + (k + 0.5) * slab
                a = axis.interpolate(max(s0 - 0.5 * slab, 0.0))
                b = axis.interpolate(min(s0 + 0.5 * slab, L))
                p = axis.interpolate(s0)
                tx, ty = b.x - a.x, b.y - a.y
                tn = np.hypot(tx, ty)
                if tn == 0:
                    continue
                piece = _section_piece(poly, p.x, p.y, -ty / tn, tx / tn, half)
                if piece is None:
                    continue
                line = piece
                if rims is not None and rim_search_m > 0:
                    line, _ = extend_to_rims(piece, rims, grid, rim_search_m, dem64 if no_rim == "highest_ground" else None,
                                             ground_segment_m)
                lev = None
                along = None
                if ground_along_axis and ground_segment_m > 0:
                    along = (np.array([tx, ty]) / tn, axis_gradient(axis, s0, dem64, grid, step, ground_segment_m))
                if reference in ("banks", "bank_lines"):
                    s, z, lev = _bank_drape(line, dem64, grid, step, ground_segment_m, bank_fit_m,
                                            "quadratic" if reference == "banks" else "lines", along)
                elif ground_segment_m > 0:
                    s, z = _ground_drape(line, dem64, grid, step, ground_segment_m, along)
                else:
                    s, x, y, z = drape(line, dem64, grid, step)
                if reference == "spill":
                    _, _, _, lev = drape(line, lev64, grid, step)
                    lev = np.interp(s, np.linspace(0.0, line.length, lev.size), lev)
                depth, area = section_profile(s, z, reference, lev)
                vol += area * slab
                ws.append(piece.length)
                ds.append(depth)
                if line is not piece or ground_segment_m > 0 or lev is not None:  # the stored section is the clipped one (width = its length), draped
                    _, x, y, z = drape(piece, dem64, grid, step)
                sec_rec.append({"polygon_id": pid, "branch": bi, "station_m": s0, "width_m": piece.length, "depth_m": depth, "area_m2": area,
                                "slab_m": slab, "reference_length_m": line.length, "geometry": shapely.LineString(np.column_stack([x, y, z]))})
        row.update({"length_m": total_len, "n_sections": len(ws), "volume_m3": vol})
        if ws:
            row.update({"mean_width_m": float(np.mean(ws)), "max_width_m": float(np.max(ws)),
                        "mean_depth_m": float(np.mean(ds)), "max_depth_m": float(np.max(ds))})
        morph.append(row)
    axes = gpd.GeoDataFrame(ax_rec or {"polygon_id": [], "branch": [], "length_m": [], "trim_m": []}, geometry="geometry" if ax_rec else [], crs=grid.crs)
    sections = gpd.GeoDataFrame(sec_rec or {"polygon_id": [], "branch": [], "station_m": [], "width_m": [], "depth_m": [], "area_m2": [], "slab_m": [],
                                        "reference_length_m": []},
                                geometry="geometry" if sec_rec else [], crs=grid.crs)
    log.info("morphometry: %d polygons, %d medial-axis branches, %d cross-sections, volume %.1f m3", len(morph), len(ax_rec), len(sec_rec),
             sum(r["volume_m3"] for r in morph))
    cols = ["polygon_id", "area_m2", "length_m", "n_sections", "mean_width_m", "max_width_m", "mean_depth_m", "max_depth_m", "volume_m3"]
    return axes, sections, pd.DataFrame(morph, columns=cols)
