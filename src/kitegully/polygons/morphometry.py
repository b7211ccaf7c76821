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
from skimage.morphology import thin

from kitegully.io.raster import GridSpec
from kitegully.polygons.skeleton import branch_paths, longest_path
from kitegully.polygons.thalweg import resample_line, snakes_smooth

log = logging.getLogger(__name__)

#: Depth reference surfaces (``polygons.morphometry.reference``).
REFERENCES = ("lower_end", "line", "spill", "banks", "bank_lines")
#: Where a section end without a rim stays (``polygons.morphometry.no_rim``).
NO_RIM = ("outline", "highest_ground")
#: Which medial-axis branches carry sections (``polygons.morphometry.branches``).
BRANCHES = ("all", "longest")


def _smooth_path(rr: np.ndarray, cc: np.ndarray, grid: GridSpec, r0: int, c0: int, smooth_step: float, alpha: float,
                 beta: float) -> shapely.LineString | None:
    xs, ys = grid.xy(r0 + rr, c0 + cc)
    xy = resample_line(np.column_stack([xs, ys]), smooth_step)
    if len(xy) < 2:
        return None
    return shapely.LineString(snakes_smooth(xy, alpha, beta))


def medial_axis(mask: np.ndarray, grid: GridSpec, r0: int, c0: int, smooth_step: float, alpha: float, beta: float) -> shapely.LineString | None:
    """Smoothed longest path of the thinned mask (sub-array whose top-left cell is (r0, c0)).

    Parameters
    ----------
    mask : ndarray (h, w) bool
        The polygon's mask; its holes are filled before thinning.
    grid : GridSpec
        The stage grid.
    r0, c0 : int
        Top-left cell of ``mask`` in the grid.
    smooth_step : float
        Vertex spacing of the smoothed line (m).
    alpha, beta : float
        Snakes weights (:func:`kitegully.polygons.thalweg.snakes_smooth`).

    Returns
    -------
    LineString or None
        The medial axis in map coordinates; None when the skeleton has no path of two cells.
    """
    skel = thin(ndi.binary_fill_holes(mask))
    rr, cc = longest_path(skel)
    if rr.size < 2:
        return None
    return _smooth_path(rr, cc, grid, r0, c0, smooth_step, alpha, beta)


def medial_network(mask: np.ndarray, grid: GridSpec, r0: int, c0: int, smooth_step: float, alpha: float, beta: float,
                   min_extension_m: float) -> list[tuple[shapely.LineString, float]]:
    """Smoothed branches of the thinned mask's pruned medial network with their trims (m).

    The first branch is the longest path (:func:`medial_axis`); each further one is a
    tributary reaching at least ``min_extension_m`` beyond its parent's edge, and its first
    ``trim`` metres (the parent's inscribed radius at the junction) lie inside the parent
    (:func:`kitegully.polygons.skeleton.branch_paths`).

    Parameters
    ----------
    mask : ndarray (h, w) bool
        The polygon's mask; its holes are filled before thinning.
    grid : GridSpec
        The stage grid.
    r0, c0 : int
        Top-left cell of ``mask`` in the grid.
    smooth_step : float
        Vertex spacing of the smoothed lines (m).
    alpha, beta : float
        Snakes weights (:func:`kitegully.polygons.thalweg.snakes_smooth`).
    min_extension_m : float
        Least reach of a tributary beyond its parent's edge (m).

    Returns
    -------
    list of (LineString, float)
        Each branch in map coordinates and its trim (m), the longest path first.
    """
    filled = ndi.binary_fill_holes(mask)
    skel = thin(filled)
    radius = ndi.distance_transform_edt(np.pad(filled, 1))[1:-1, 1:-1]
    out = []
    for rr, cc, trim in branch_paths(skel, radius, min_extension_m / grid.cell):
        if rr.size < 2:
            continue
        line = _smooth_path(rr, cc, grid, r0, c0, smooth_step, alpha, beta)
        if line is not None and line.length > 0:
            out.append((line, trim * grid.cell))
    return out


def open_at_edges(sub: np.ndarray, r0: int, c0: int, shape: tuple[int, int], gap: int = 0) -> tuple[np.ndarray, int, int]:
    """A polygon's mask continued straight on across the DEM's edge where it reaches it.

    Thinning sees the DEM's edge as the polygon's end, and a polygon cut by the edge gets
    an axis that forks into the two corners of the cut. Continued by repeating its outermost
    rows or columns up to the edge and for twice its largest inscribed radius (plus 2 cells)
    beyond, the mask's skeleton runs on through the edge; the axis is then cut back to the
    DEM (:func:`clip_to_extent`).

    Parameters
    ----------
    sub : ndarray bool (h, w)
        The polygon's mask in its bounding window.
    r0, c0 : int
        The window's top-left cell in the DEM.
    shape : tuple
        The DEM's shape (H, W).
    gap : int
        A polygon within this many cells of an edge reaches it (the dam on the edge and its
        growth stand between a pool and the edge).

    Returns
    -------
    mask : ndarray bool
        The continued mask (``sub`` itself where the polygon reaches no edge).
    top, left : int
        The returned mask's top-left cell in the DEM (may be negative).
    """
    H, W = shape
    rows, cols = np.nonzero(sub.any(axis=1))[0], np.nonzero(sub.any(axis=0))[0]
    if rows.size == 0:
        return sub, r0, c0
    R0, R1, C0, C1 = r0 + rows[0], r0 + rows[-1], c0 + cols[0], c0 + cols[-1]
    sides = (R0 <= gap, H - 1 - R1 <= gap, C0 <= gap, W - 1 - C1 <= gap)
    if not any(sides):
        return sub, r0, c0
    tight = sub[rows[0]:rows[-1] + 1, cols[0]:cols[-1] + 1].copy()
    e = int(2.0 * ndi.distance_transform_edt(np.pad(tight, 1)).max()) + 2
    k = min(2 * gap + 3, *tight.shape)  # the cut's profile: what the outermost k lines hold (the closing frays the last one)
    if sides[0]:
        tight[:k] = tight[:k].any(axis=0)
    if sides[1]:
        tight[-k:] = tight[-k:].any(axis=0)
    if sides[2]:
        tight[:, :k] = tight[:, :k].any(axis=1)[:, None]
    if sides[3]:
        tight[:, -k:] = tight[:, -k:].any(axis=1)[:, None]
    pads = ((R0 + e if sides[0] else 0, H - 1 - R1 + e if sides[1] else 0),
            (C0 + e if sides[2] else 0, W - 1 - C1 + e if sides[3] else 0))
    return np.pad(tight, pads, mode="edge"), R0 - pads[0][0], C0 - pads[1][0]


def clip_to_extent(line: shapely.LineString, grid: GridSpec) -> shapely.LineString | None:
    """The longest piece of ``line`` inside the grid's extent (None if nothing is left)."""
    piece = line.intersection(shapely.box(*grid.bounds))
    parts = [g for g in getattr(piece, "geoms", [piece]) if g.geom_type == "LineString" and g.length > 0]
    return max(parts, key=lambda g: g.length) if parts else None


def prolong_to_outline(axis: shapely.LineString, poly: shapely.Polygon | shapely.MultiPolygon, start: bool, end: bool,
                       look_m: float) -> shapely.LineString:
    """The axis prolonged at its free ends, straight on, to the polygon outline.

    Thinning stops a medial axis at the centre of the last inscribed circle, about a half
    width short of the polygon's end; prolonged, the slabs of its sections tile the polygon's
    whole length. The direction is that of the last ``look_m`` of the axis, and a prolongation
    is at most twice the end's distance to the outline plus 1 m (a rounded or square end).

    Parameters
    ----------
    axis : LineString
        The medial axis.
    poly : Polygon or MultiPolygon
        The polygon whose outline the ends are prolonged to.
    start, end : bool
        Prolong the axis' first and last end.
    look_m : float
        Length of the axis' end piece that gives the direction (m).

    Returns
    -------
    LineString
        The prolonged axis; an end whose ray meets no outline stays as it is.
    """
    xy = np.asarray(axis.coords)[:, :2]
    if len(xy) < 2 or axis.length == 0:
        return axis
    boundary = poly.boundary

    def tip(p_end: np.ndarray, p_in: np.ndarray) -> np.ndarray | None:
        d = p_end - p_in
        n = np.hypot(*d)
        if n == 0:
            return None
        reach = 2.0 * boundary.distance(shapely.Point(p_end)) + 1.0
        ray = shapely.LineString([p_end, p_end + d / n * reach])
        hit = ray.intersection(boundary)
        if hit.is_empty:
            return None
        pts = np.asarray([g.coords[0] for g in getattr(hit, "geoms", [hit]) if not g.is_empty])
        return pts[np.argmin(np.hypot(*(pts[:, :2] - p_end).T))][:2]

    L = axis.length
    out = [xy]
    if start:
        q = np.asarray(axis.interpolate(min(look_m, L)).coords[0])[:2]
        t = tip(xy[0], q)
        if t is not None:
            out.insert(0, t[None, :])
    if end:
        q = np.asarray(axis.interpolate(max(L - look_m, 0.0)).coords[0])[:2]
        t = tip(xy[-1], q)
        if t is not None:
            out.append(t[None, :])
    return shapely.LineString(np.concatenate(out))


def without_holes(poly: shapely.Polygon | shapely.MultiPolygon) -> shapely.Polygon | shapely.MultiPolygon:
    """The polygon (or each part of a multipolygon) with its holes filled.

    The medial axes are thinned from the filled mask (:func:`medial_axis`,
    :func:`medial_network`), so the sections across them are clipped to the same filled
    outline: a hole (a knot of dam cells the closing did not bridge, an island of
    vegetation) would otherwise cut a section short at its edge, and the section would miss
    the width and area beyond it.
    """
    parts = [shapely.Polygon(g.exterior) for g in getattr(poly, "geoms", [poly]) if g.geom_type == "Polygon"]
    return parts[0] if len(parts) == 1 else shapely.MultiPolygon(parts)


def _section_piece(poly, px: float, py: float, nx: float, ny: float, half: float):
    line = shapely.LineString([(px - half * nx, py - half * ny), (px + half * nx, py + half * ny)])
    inter = line.intersection(poly)
    parts = [g for g in getattr(inter, "geoms", [inter]) if g.geom_type == "LineString" and not g.is_empty]
    if not parts:
        return None
    pt = shapely.Point(px, py)
    return min(parts, key=lambda g: g.distance(pt))


def drape(line: shapely.LineString, surface: np.ndarray, grid: GridSpec, step: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Points every ``step`` m along ``line`` (ends included): s, x, y and bilinear z.

    Parameters
    ----------
    line : LineString
        Line in map coordinates.
    surface : ndarray (H, W)
        Surface to sample (m).
    grid : GridSpec
        Grid of ``surface``.
    step : float
        Largest sample spacing (m); the samples are spread evenly over the line.

    Returns
    -------
    s, x, y, z : ndarray (n,)
        Distance along the line (m), map coordinates and the surface's elevation (m).
    """
    n = max(int(np.ceil(line.length / step)), 1)
    s = np.linspace(0.0, line.length, n + 1)
    pts = shapely.line_interpolate_point(line, s)
    x, y = shapely.get_x(pts), shapely.get_y(pts)
    r, c = grid.rowcol(x, y)
    z = map_coordinates(surface, [r, c], order=1, mode="nearest")
    return s, x, y, z


def axis_gradient(axis: shapely.LineString, s0: float, dem: np.ndarray, grid: GridSpec, step: float, segment_m: float) -> float:
    """The floor's gradient along a medial axis at ``s0`` (m/m, positive uphill in the axis' direction).

    The slope of a straight line fitted (least squares) to the axis' ground profile (the DEM
    draped along the axis from ``s0 − 2·segment_m`` to ``s0 + 2·segment_m``, opened with
    ``segment_m`` as :func:`ground_profile`, so that a clump in the channel does not tilt it)
    over ``s0 ± segment_m``. 0 where the axis is too short for two samples. O(segment / step).

    Parameters
    ----------
    axis : LineString
        The medial axis.
    s0 : float
        Position along the axis (m).
    dem : ndarray (H, W)
        DEM (m).
    grid : GridSpec
        Grid of ``dem``.
    step : float
        Sample spacing along the axis (m).
    segment_m : float
        Half-length of the fitted stretch and length of the opening segment (m).

    Returns
    -------
    float
        Gradient (m/m).
    """
    a, b = max(s0 - 2.0 * segment_m, 0.0), min(s0 + 2.0 * segment_m, axis.length)
    if b - a < 2.0 * step:
        return 0.0
    piece = shapely.ops.substring(axis, a, b)
    s, _, _, z = drape(piece, dem, grid, step)
    g = ground_profile(z, float(s[1] - s[0]) if s.size > 1 else step, segment_m)
    tau = s + a - s0
    sel = (np.abs(tau) <= segment_m + 1e-9) & np.isfinite(g)
    if sel.sum() < 2:
        return 0.0
    return float(np.polyfit(tau[sel], g[sel], 1)[0])


def drape_opened_along(line: shapely.LineString, surface: np.ndarray, grid: GridSpec, step: float, along: np.ndarray,
                       gradient: float, segment_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`drape`, with each sample's elevation opened along the gully (the ground between plants along the strip).

    The line is draped again shifted by τ in [−``segment_m``, +``segment_m``] (every ``step``)
    along the unit vector ``along`` (the gully axis), each copy detrended by ``gradient`` · τ
    (the floor's gradient along the axis, :func:`axis_gradient`, so that a rim is not bevelled
    by the gully's fall), and at each position the samples along τ are opened with a
    ``segment_m`` segment (:func:`ground_profile`'s 1-D grey opening); the value at τ = 0 is
    returned. A plant clump narrower than the segment along the strip is removed where ground
    shows beside it along the gully; a clump the opening across the section cannot see past
    (its gap to the next clump across is filled by the matching window) is seen past along it.
    Never above :func:`drape`'s z (the opening is anti-extensive and τ = 0 is not detrended).

    Parameters
    ----------
    line : LineString
        The section in map coordinates.
    surface : ndarray (H, W)
        Surface to sample (m).
    grid : GridSpec
        Grid of ``surface``.
    step : float
        Sample spacing along the line and along the axis (m).
    along : ndarray (2,)
        Unit vector of the gully axis (x east, y north).
    gradient : float
        Floor gradient along ``along`` (m/m).
    segment_m : float
        Length of the opening segment along the axis (m); 0 = :func:`drape` unchanged.

    Returns
    -------
    s, x, y, z : ndarray
        As :func:`drape`. O(n · segment / step) for n samples.
    """
    s, x, y, z0 = drape(line, surface, grid, step)
    k = int(round(segment_m / step))
    if segment_m <= 0 or k < 1:
        return s, x, y, z0
    tau = np.arange(-k, k + 1) * step
    shifted = tau != 0  # the τ = 0 row is drape's own z0, not sampled twice
    xs = x[None, :] + tau[shifted, None] * along[0]
    ys = y[None, :] + tau[shifted, None] * along[1]
    r, c = grid.rowcol(xs.ravel(), ys.ravel())
    zz = np.empty((tau.size, s.size))
    zz[shifted] = map_coordinates(surface, [r, c], order=1, mode="nearest").reshape(xs.shape) - gradient * tau[shifted, None]
    zz[k] = z0
    ok = np.isfinite(zz)
    zz = np.where(ok, zz, np.nanmax(zz) if ok.any() else 0.0)
    opened = ndi.grey_opening(zz, size=(k + 1, 1), mode="nearest")[k]
    return s, x, y, np.where(np.isfinite(z0), np.minimum(opened, z0), z0)


def section_profile(s: np.ndarray, z: np.ndarray, reference: str, level: np.ndarray | None = None) -> tuple[float, float]:
    """(max depth, cross-sectional area) of a draped section below the reference surface.

    ``level`` is the reference surface itself along ``s`` for ``spill`` (the pool level),
    ``banks`` and ``bank_lines`` (:func:`bank_reference`).

    Parameters
    ----------
    s : ndarray (n,)
        Distance along the section (m).
    z : ndarray (n,)
        Elevations at ``s`` (m).
    reference : str
        Depth reference (:data:`REFERENCES`).
    level : ndarray (n,) or None
        Reference surface at ``s`` (m) for ``spill``, ``banks`` and ``bank_lines``.

    Returns
    -------
    depth : float
        Largest depth below the reference (m).
    area : float
        Cross-sectional area below the reference (m²).
    """
    if reference == "lower_end":
        zr = np.full_like(z, min(z[0], z[-1]))
    elif reference == "line":
        zr = z[0] + (z[-1] - z[0]) * (s / s[-1] if s[-1] > 0 else 0.0)
    elif reference in ("spill", "banks", "bank_lines"):
        zr = level
    else:
        raise ValueError(f"reference must be one of {REFERENCES}, got {reference!r}")
    d = np.maximum(np.nan_to_num(zr - z, nan=0.0), 0.0)
    area = float(np.sum(0.5 * (d[1:] + d[:-1]) * np.diff(s))) if len(s) > 1 else 0.0
    return float(d.max()), area


def ground_profile(z: np.ndarray, step: float, segment_m: float) -> np.ndarray:
    """Ground of a draped profile under plants narrower than ``segment_m``: 1-D grey opening.

    The opening (minimum, then maximum, over ``segment_m``) removes every bump narrower than
    the segment (a shrub clump on a rim stands on ground the segment reaches beside it) and
    keeps every concave part (a gully floor) and every straight one (a field's cross slope)
    unchanged (the progressive morphological filter of Zhang et al. 2003, one window, along
    the section). Across a gully the profile's only convex corners are the rims: a rim whose
    field rises outwards is kept; one whose field falls outwards at cross slope c is lowered
    by at most c · ``segment_m``.

    Parameters
    ----------
    z : ndarray (n,)
        Elevations every ``step`` m along the section (m); NaN are left as they are.
    step : float
        Sample spacing (m).
    segment_m : float
        Segment length (m): the widest plant clump to be removed; 0 = ``z`` unchanged.

    Returns
    -------
    ndarray (n,)
        The ground profile (≤ ``z``); within one segment of either end it may lie low (the
        opening sees past the end), so callers drape the section prolonged by one segment at
        both ends (:func:`_ground_drape`). O(n · segment / step).
    """
    k = int(round(segment_m / step)) + 1
    if segment_m <= 0 or k < 2 or z.size < k:
        return z
    ok = np.isfinite(z)
    zz = np.where(ok, z, np.nanmax(z) if ok.any() else 0.0)
    g = ndi.grey_opening(zz, size=k, mode="nearest")
    return np.where(ok, g, z)


#: Samples within this distance (m) of a section end count as on it (:func:`bank_reference`).
_END_TOL = 1e-9


def bank_reference(s: np.ndarray, z: np.ndarray, length: float, fit_m: float, model: str = "quadratic") -> np.ndarray:
    """Pre-incision surface across a gully from its two banks, on the samples ``0 <= s <= length``.

    The banks are the profile over ``fit_m`` outwards from each reference end (``s`` in
    [−fit_m, 0] and [length, length + fit_m]).

    - ``quadratic``: one parabola z = a + b·s + c·s² fitted (least squares) to both banks at once:
      on a plane (a hillside tilted across the gully) it is that plane, i.e. the straight line
      between the ends (``reference="line"``); in a hollow of constant curvature κ (where flow
      converges and gullies cut in) it is the hollow's own floor, κ·B²/8 below the straight line
      at the middle of a section of width B between the ends; in a V-shaped valley floor (sides
      of slope c) it takes part of the c·B/2 by which the straight line stands above the V.
    - ``lines``: a straight line fitted to each bank, both extended across the gully and blended
      linearly, z_ref(s) = (1 − s/L)·left(s) + (s/L)·right(s): exact on a plane and in a V-shaped
      valley floor, but in a hollow each bank's slope, taken a lever arm away from the gully,
      extrapolates below the hollow's floor.

    With fewer than two finite samples on either bank (no slope there) the straight line between
    the ends is returned.

    Parameters
    ----------
    s : ndarray (n,)
        Positions along the section prolonged beyond both reference ends (m; 0 = first end),
        increasing.
    z : ndarray (n,)
        Ground elevations at ``s`` (m); NaN = no data.
    length : float
        Position of the second reference end (m).
    fit_m : float
        Length of each bank beyond its end (m).
    model : str
        ``quadratic`` or ``lines``.

    Returns
    -------
    ndarray
        z_ref at the samples ``0 <= s <= length``. O(n).
    """
    inner = (s >= -_END_TOL) & (s <= length + _END_TOL)
    si, zi = s[inner], z[inner]
    L = max(float(length), 1e-9)
    t = np.clip(si / L, 0.0, 1.0)
    chord = zi[0] + (zi[-1] - zi[0]) * t if zi.size else zi
    left = (s >= -fit_m - _END_TOL) & (s <= _END_TOL) & np.isfinite(z)
    right = (s >= length - _END_TOL) & (s <= length + fit_m + _END_TOL) & np.isfinite(z)
    if model not in ("quadratic", "lines"):
        raise ValueError(f"model must be 'quadratic' or 'lines', got {model!r}")
    if left.sum() < 2 or right.sum() < 2:
        return chord
    if model == "quadratic":
        sel = left | right
        c2, c1, c0 = np.polyfit(s[sel], z[sel], 2)
        return c0 + si * (c1 + si * c2)
    else:
        bl, al = np.polyfit(s[left], z[left], 1)
        br, ar = np.polyfit(s[right], z[right], 1)
        return (1.0 - t) * (al + bl * si) + t * (ar + br * si)


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
    left, right = s_all < -_END_TOL, s_all > L + _END_TOL
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
