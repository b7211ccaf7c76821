"""Medial axes of the gully polygons (Höfle et al. 2013 sect. 4.2, Fig. 10).

Grassfire thinning of a polygon's raster to a one-cell skeleton, then its longest path (the
paper's pruned medial axis) or its pruned medial network
(:func:`kitegully.polygons.skeleton.branch_paths`), smoothed with snakes and optionally
prolonged at their free ends to the outline (:func:`prolong_to_outline`). The sections across
them are :mod:`kitegully.polygons.morphometry`'s.
"""

from __future__ import annotations

import numpy as np
import scipy.ndimage as ndi
import shapely
from skimage.morphology import thin

from kitegully.io.raster import GridSpec
from kitegully.polygons.skeleton import branch_paths, longest_path
from kitegully.polygons.thalweg import resample_line, snakes_smooth


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
