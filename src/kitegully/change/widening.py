"""Gully widening per cross-section: the width of each epoch-1 section measured on both DEMs.

The polygons stage cuts cross-sections across each gully polygon of epoch 1
(``cross_sections.gpkg``: one line per section, clipped to the polygon). Widening needs
the same line on both dates, with the same edge rule on both, so that the rule's own bias
cancels in the difference:

1. each section line is extended by ``margin_m`` at both ends along its own direction
   (room for the banks to move outwards), and both DEMs are draped on it every half cell
   (:func:`kitegully.polygons.profiles.drape`);
2. per DEM, the reference is the straight line between the profile's two end levels
   (median of the outer ``end_m`` at each end), the depth d(s) = reference − z;
3. from the deepest point inside the epoch-1 section, the edges are where d first falls
   below ``min_depth_m`` on each side (linear interpolation between samples); width = the
   distance between the two edges, ``widening_m`` = width₂ − width₁.

O(sections × profile samples).
"""

from __future__ import annotations

import logging

import geopandas as gpd
import numpy as np
import pandas as pd
import shapely

from kitegully.io.raster import GridSpec
from kitegully.polygons.profiles import drape

log = logging.getLogger(__name__)

#: Largest share of nodata samples on a profile that is still interpolated ([I] a fifth).
MAX_NODATA = 0.2

COLUMNS = ["section_id", "polygon_id", "station_m", "width_polygon1_m", "width1_m", "width2_m", "widening_m",
           "depth1_m", "depth2_m"]


def extend_line(line: shapely.LineString, margin_m: float) -> shapely.LineString:
    """The straight line through a section's two ends, longer by ``margin_m`` at each end (2-D)."""
    (x0, y0), (x1, y1) = np.asarray(line.coords)[0, :2], np.asarray(line.coords)[-1, :2]
    L = float(np.hypot(x1 - x0, y1 - y0))
    if L == 0:
        return shapely.LineString([(x0, y0), (x1, y1)])
    ux, uy = (x1 - x0) / L, (y1 - y0) / L
    return shapely.LineString([(x0 - margin_m * ux, y0 - margin_m * uy), (x1 + margin_m * ux, y1 + margin_m * uy)])


def edge_width(s: np.ndarray, z: np.ndarray, inner: tuple[float, float], min_depth_m: float, end_m: float) -> tuple[float, float]:
    """(width, max depth) of the channel on one draped profile, by the rule of the module docstring.

    ``inner`` is the (start, end) of the epoch-1 section along ``s``. Nodata samples are
    interpolated along the profile when they are at most ``MAX_NODATA`` of it. NaN width when
    the profile has more nodata, no cell deeper than ``min_depth_m`` inside ``inner``, or an
    edge that does not close before the profile ends (the banks moved beyond the margin).

    Parameters
    ----------
    s : ndarray
        Stations along the profile (m).
    z : ndarray
        Elevation at each station (m); NaN is nodata.
    inner : tuple of float
        See above (m).
    min_depth_m : float
        Depth below the reference line (m) at which the edges lie.
    end_m : float
        Length of each end (m) whose median elevation sets the reference line.

    Returns
    -------
    width, depth : float
        Channel width and its greatest depth inside ``inner`` (m); both NaN for a profile of fewer than
        5 samples or too much nodata, or an empty ``inner``.
    """
    ok = np.isfinite(z)
    if s.size < 5 or ok.mean() < 1.0 - MAX_NODATA or ok.sum() < 2:
        return np.nan, np.nan
    if not ok.all():
        z = np.interp(s, s[ok], z[ok])
    a, b = s <= s[0] + end_m, s >= s[-1] - end_m
    za, zb = float(np.median(z[a])), float(np.median(z[b]))
    ref = za + (zb - za) * (s - s[0]) / (s[-1] - s[0])
    d = ref - z
    inside = (s >= inner[0]) & (s <= inner[1])
    if not inside.any():
        return np.nan, np.nan
    k = int(np.flatnonzero(inside)[np.argmax(d[inside])])
    if d[k] < min_depth_m:
        return np.nan, float(d[k])
    below = np.flatnonzero(d < min_depth_m)
    left, right = below[below < k], below[below > k]
    if left.size == 0 or right.size == 0:
        return np.nan, float(d[k])
    i, j = int(left[-1]), int(right[0])

    def cross(p: int, q: int) -> float:  # s where d crosses min_depth between samples p and q
        return float(s[p] + (min_depth_m - d[p]) / (d[q] - d[p]) * (s[q] - s[p]))

    return cross(j - 1, j) - cross(i, i + 1), float(d[k])


def measure_widening(z1: np.ndarray, z2: np.ndarray, grid: GridSpec, sections: gpd.GeoDataFrame, margin_m: float,
                     min_depth_m: float, end_m: float) -> pd.DataFrame:
    """Width of every epoch-1 cross-section on both DEMs and the widening (m).

    Parameters
    ----------
    z1, z2 : ndarray (H, W)
        Epoch-1 and co-registered epoch-2 DEMs on ``grid`` (m).
    sections : GeoDataFrame
        The polygons stage's ``cross_sections.gpkg`` (``polygon_id``, ``station_m``,
        ``width_m``, line geometry), in the grid's CRS.
    margin_m, min_depth_m, end_m : float
        See the module docstring.

    Returns
    -------
    DataFrame
        :data:`COLUMNS`, one row per section (``section_id`` = its row number in the file).
    """
    rows = []
    step = 0.5 * grid.cell
    surfaces = (np.asarray(z1, np.float64), np.asarray(z2, np.float64))  # once, not per section
    for i, (pid, st, wp, geom) in enumerate(zip(sections["polygon_id"], sections["station_m"], sections["width_m"],
                                               sections.geometry)):
        line = extend_line(geom, margin_m)
        inner = (margin_m, line.length - margin_m)
        out = []
        for z in surfaces:
            s, _, _, zz = drape(line, z, grid, step)
            out.append(edge_width(s, zz, inner, min_depth_m, end_m))
        (w1, d1), (w2, d2) = out
        rows.append(dict(section_id=i, polygon_id=pid, station_m=st, width_polygon1_m=wp, width1_m=w1, width2_m=w2,
                         widening_m=w2 - w1, depth1_m=d1, depth2_m=d2))
    df = pd.DataFrame(rows, columns=COLUMNS)
    log.info("widening: %d sections, %d measured on both DEMs, median widening %.2f m", len(df),
             int(df["widening_m"].notna().sum()), float(df["widening_m"].median()) if len(df) else np.nan)
    return df


def true_widths(sections: gpd.GeoDataFrame, polygons: gpd.GeoDataFrame, margin_m: float) -> np.ndarray:
    """Length of each extended section line inside the true gully polygons (the piece nearest its middle), m.

    Evaluation only (true polygons of a twin).

    Parameters
    ----------
    sections : GeoDataFrame
        The epoch-1 cross-sections (lines).
    polygons : GeoDataFrame
        The true gully polygons.
    margin_m : float
        Extension of each section line at both ends (m).

    Returns
    -------
    ndarray
        Width of each section (m); 0 where its line misses the polygons.
    """

    union = shapely.union_all(polygons.geometry.to_numpy()) if len(polygons) else shapely.Polygon()
    out = []
    for geom in sections.geometry:
        line = extend_line(geom, margin_m)
        mid = line.interpolate(0.5, normalized=True)
        inter = line.intersection(union)
        parts = [g for g in getattr(inter, "geoms", [inter]) if isinstance(g, shapely.LineString) and not g.is_empty]
        out.append(min(parts, key=lambda g: g.distance(mid)).length if parts else 0.0)
    return np.asarray(out, float)
