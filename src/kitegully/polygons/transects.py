"""Artificial dams orthogonal to the thalweg (Höfle et al. 2013 sect. 4.1).

One transect every ``spacing_m`` along each thalweg line, ``half_length_m`` to each side.
Where a transect crosses breaklines on both sides of the thalweg only its middle part,
between the nearest crossing on each side, is kept; otherwise it keeps its full length.
Optionally ([I]) the next transect comes earlier where the thalweg has dropped by
``max_drop_m`` since the last one, so that no pool's floor falls by more than that
between its dams (the paper's advice for steep channels), and ([I]) the survey's edge
becomes a dam where a thalweg leaves the DEM (:func:`survey_edge_dams`).
"""

from __future__ import annotations

import numpy as np
import shapely
from scipy.ndimage import binary_erosion, label, map_coordinates, minimum_filter
from scipy.spatial import cKDTree

from kitegully.io.raster import GridSpec


def station_floor(dem: np.ndarray) -> np.ndarray:
    """The 3 × 3 minimum of the DEM (NaN as its maximum) that :func:`transect_stations` follows.

    Computed once per DEM and passed to every line's :func:`transect_stations` (``floor=``):
    computed inside each call it made the transects O(lines × cells), quadratic in the
    site's area (issue 21: 2.5 s of 6 s on the default twin, minutes at full size).
    """
    return minimum_filter(np.nan_to_num(dem, nan=np.nanmax(dem)), size=3, mode="nearest")


def transect_stations(line: shapely.LineString, spacing: float, dem: np.ndarray | None = None, grid: GridSpec | None = None,
                      max_drop: float | None = None, min_spacing: float = 0.0, floor: np.ndarray | None = None) -> np.ndarray:
    """Distances along ``line`` (m) where the transects stand.

    Every ``spacing`` m starting half a spacing from the upper end; with ``max_drop``, a
    station also where the (3 × 3 minimum of the) DEM along the line has dropped by
    ``max_drop`` since the previous station, but never closer than ``min_spacing``. A line
    too short for any station gets one at its middle (a thalweg fragment still dams its
    reach). ``floor``: :func:`station_floor` of ``dem`` when already computed.

    Parameters
    ----------
    line : LineString
        Thalweg line, from its upper end.
    spacing : float
        Transect spacing (m).
    dem : ndarray (H, W) or None
        DEM (m) for the drop rule; None = regular spacing only.
    grid : GridSpec or None
        Grid of ``dem``; needed with ``max_drop``.
    max_drop : float or None
        Drop of the floor that sets a station early (m); None = regular spacing only.
    min_spacing : float
        Shortest distance between stations with ``max_drop`` (m).
    floor : ndarray (H, W) or None
        :func:`station_floor` of ``dem``; None = computed here.

    Returns
    -------
    ndarray
        Station distances along ``line`` (m).
    """
    L = line.length
    if max_drop is None or dem is None:
        return np.arange(0.5 * spacing, L, spacing) if L > 0.5 * spacing else np.array([0.5 * L])
    step = grid.cell
    s = np.arange(0.0, L + 1e-9, step)
    pts = shapely.line_interpolate_point(line, s)
    x, y = shapely.get_x(pts), shapely.get_y(pts)
    r, c = grid.rowcol(x, y)
    zmin = station_floor(dem) if floor is None else floor
    z = map_coordinates(zmin, [r, c], order=1, mode="nearest")
    out = []
    last_s, last_z = 0.0, z[0]
    for si, zi in zip(s, z):
        ds = si - last_s
        if ds < min_spacing:
            continue
        first = not out
        due = ds >= (0.5 * spacing if first else spacing)
        steep = abs(last_z - zi) >= max_drop
        if due or steep:
            out.append(si)
            last_s, last_z = si, zi
    return np.asarray(out) if out else np.array([0.5 * L])


def make_transects(line: shapely.LineString, stations: np.ndarray, half_length: float, tangent_half_window: float) -> list[shapely.LineString]:
    """Straight transects through the stations, orthogonal to the line's mean direction
    within ``± tangent_half_window`` m of each station.

    Parameters
    ----------
    line : LineString
        Thalweg line.
    stations : ndarray
        Distances along ``line`` (m).
    half_length : float
        Transect length on each side of the line (m).
    tangent_half_window : float
        Half-length of the stretch that gives the line's direction (m).

    Returns
    -------
    list of LineString
        Two-point transects, one per station; a station whose stretch has no length gets none.
    """
    out = []
    L = line.length
    for s in stations:
        a = line.interpolate(max(s - tangent_half_window, 0.0))
        b = line.interpolate(min(s + tangent_half_window, L))
        p = line.interpolate(s)
        tx, ty = b.x - a.x, b.y - a.y
        n = np.hypot(tx, ty)
        if n == 0:
            continue
        nx, ny = -ty / n, tx / n
        out.append(shapely.LineString([(p.x - half_length * nx, p.y - half_length * ny), (p.x + half_length * nx, p.y + half_length * ny)]))
    return out


def clip_transects(transects: list[shapely.LineString], breaklines: list[shapely.LineString]) -> tuple[list[shapely.LineString], np.ndarray]:
    """Keep the middle part between the nearest breakline crossings where both sides cross.

    Parameters
    ----------
    transects : list of LineString
        Two-point transects whose midpoint is on the thalweg.
    breaklines : list of LineString
        Vector breaklines.

    Returns
    -------
    clipped : list of LineString
    was_clipped : ndarray bool
    """
    tree = shapely.STRtree(breaklines) if breaklines else None
    out, flags = [], []
    for t in transects:
        (x0, y0), (x1, y1) = t.coords[0], t.coords[-1]
        mx, my = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
        ux, uy = (x1 - x0) / t.length, (y1 - y0) / t.length
        offs = []
        if tree is not None:
            for i in tree.query(t, predicate="intersects"):
                inter = t.intersection(breaklines[i])
                for g in getattr(inter, "geoms", [inter]):
                    if g.is_empty:
                        continue
                    for px, py in np.asarray(g.coords if g.geom_type != "Point" else [g.coords[0]]):
                        offs.append((px - mx) * ux + (py - my) * uy)
        offs = np.asarray(offs)
        neg = offs[offs < 0]
        pos = offs[offs > 0]
        if neg.size and pos.size:
            a, b = neg.max(), pos.min()
            out.append(shapely.LineString([(mx + a * ux, my + a * uy), (mx + b * ux, my + b * uy)]))
            flags.append(True)
        else:
            out.append(t)
            flags.append(False)
    return out, np.asarray(flags, bool)


def outlet_ends(lines: list[shapely.LineString], dem: np.ndarray, grid: GridSpec,
                floor: np.ndarray | None = None) -> np.ndarray:
    """The lower end of each line (map coordinates, (n, 2)): where a thalweg's flow leaves it.

    Ends are compared on the 3 × 3 minimum of the DEM (:func:`station_floor`), the floor
    the transects follow (``floor``: that raster when already computed); a line whose ends
    stand equally high gives both.

    Parameters
    ----------
    lines : list of LineString
        Thalweg lines.
    dem : ndarray (H, W)
        DEM (m); used only when ``floor`` is None.
    grid : GridSpec
        Grid of ``dem``.
    floor : ndarray (H, W) or None
        :func:`station_floor` of ``dem``; None = computed here.

    Returns
    -------
    ndarray (k, 2)
        Map coordinates of the outlet ends, in line order.
    """
    if not lines:
        return np.zeros((0, 2))
    floor = station_floor(dem) if floor is None else floor
    ends = np.array([[ln.coords[0][:2], ln.coords[-1][:2]] for ln in lines])  # (n, 2 ends, xy)
    r, c = grid.rowcol(ends[..., 0].ravel(), ends[..., 1].ravel())
    z = map_coordinates(floor, [r, c], order=1, mode="nearest").reshape(-1, 2)
    keep = np.column_stack([z[:, 0] <= z[:, 1], z[:, 1] <= z[:, 0]])
    return ends[keep]


def survey_edge_dams(ends_xy: np.ndarray, dem: np.ndarray, grid: GridSpec, half_length: float, reach: float,
                     blocked: np.ndarray) -> np.ndarray:
    """Dams along the survey's edge where a thalweg leaves the DEM ([I] the edge as a transect).

    A gully that runs off the surveyed area has no dam below its last transect: the sink fill
    drains that reach over the DEM's edge (or into a void left empty, such as open water), so
    it never holds a pool and the gully's lowest, often widest reach gets no polygon. Where a
    thalweg's outlet end lies within ``reach`` of the edge, the edge cells within ``half_length``
    of the edge cell nearest to that end become a dam, the edge's own transect; like a transect
    it stops at the breaklines (``blocked``: their barrier band) it meets on either side. Only
    outlets: a dam where a gully enters the survey would hold the water of the reach above the
    first transect, which otherwise drains up and out, as a false pool.

    Parameters
    ----------
    ends_xy : ndarray (n, 2)
        Map coordinates of the thalweg lines' outlet ends (:func:`outlet_ends`).
    dem : ndarray (H, W)
        Stage DEM, NaN where nothing was surveyed (left empty).
    grid : GridSpec
        Its grid.
    half_length : float
        Dam length on each side of the exit point (m): the transects' half length.
    reach : float
        Largest distance (m) from a thalweg end to the edge for that end to leave the DEM.
    blocked : ndarray bool (H, W)
        Cells a dam does not cross (the breaklines' barrier band).

    Returns
    -------
    ndarray bool (H, W)
        Dam cells on the edge: valid cells with a neighbour outside the DEM or left empty.

    Notes
    -----
    O(n_edge log n_edge) for the edge cells' KD-tree plus O(half_length² / cell²) per end.
    """
    valid = np.isfinite(dem)
    edge = valid & ~binary_erosion(valid, structure=np.ones((3, 3), bool), border_value=0)
    out = np.zeros_like(edge)
    er, ec = np.nonzero(edge)
    if er.size == 0 or len(ends_xy) == 0:
        return out
    r, c = grid.rowcol(np.asarray(ends_xy)[:, 0], np.asarray(ends_xy)[:, 1])
    dist, idx = cKDTree(np.column_stack([er, ec])).query(np.column_stack([r, c]))
    h = int(np.ceil(half_length / grid.cell))
    H, W = edge.shape
    for d, i in zip(dist, idx):
        if d * grid.cell > reach:
            continue
        r0, c0 = er[i], ec[i]
        rs, re_ = max(r0 - h, 0), min(r0 + h + 1, H)
        cs, ce = max(c0 - h, 0), min(c0 + h + 1, W)
        rr, cc = np.mgrid[rs:re_, cs:ce]
        sub = edge[rs:re_, cs:ce] & ~blocked[rs:re_, cs:ce] & (np.hypot(rr - r0, cc - c0) <= h)
        if not sub[r0 - rs, c0 - cs]:
            continue  # the thalweg leaves across a breakline: that breakline already closes it
        lab, _ = label(sub, structure=np.ones((3, 3), bool))
        out[rs:re_, cs:ce] |= lab == lab[r0 - rs, c0 - cs]
    return out
