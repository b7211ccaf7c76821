"""The twin's true gullies as vectors: centrelines with their reach geometry, polygons and heads."""

from __future__ import annotations

import geopandas as gpd
import numpy as np
import shapely
from shapely.geometry import LineString, Point

from kitegully.twin import gullies as gl, survey


def centrelines(network: list[gl.Gully], min_depth: float, reach_length: float, crs: str) -> gpd.GeoDataFrame:
    """Truth centrelines as reaches of about ``reach_length`` m where depth ≥ ``min_depth``.

    Parameters
    ----------
    network : list of Gully
        The network.
    min_depth : float
        Least depth of a mapped centreline (m).
    reach_length : float
        Target reach length (m).
    crs : str
        Site CRS.

    Returns
    -------
    GeoDataFrame
        One line per reach: ``gully_id, kind, bank, shape``, mean ``width_m`` and ``depth_m``,
        ``width_min_m, depth_min_m, depth_max_m, length_m``.
    """
    recs = []
    for g in network:
        s = g.s
        for a, b in survey._runs(g.depth >= min_depth):
            if b - a < 2:
                continue
            n_reach = max(1, int(round((s[b - 1] - s[a]) / reach_length)))
            edges = np.unique(np.round(np.linspace(a, b - 1, n_reach + 1)).astype(int))
            for i0, i1 in zip(edges[:-1], edges[1:]):
                sl = slice(i0, i1 + 1)
                recs.append({
                    "gully_id": g.gully_id, "kind": g.kind, "bank": g.bank, "shape": g.shape,
                    "width_m": float(np.mean(g.width[sl])), "depth_m": float(np.mean(g.depth[sl])),
                    "width_min_m": float(np.min(g.width[sl])), "depth_min_m": float(np.min(g.depth[sl])),
                    "depth_max_m": float(np.max(g.depth[sl])), "length_m": float(s[i1] - s[i0]),
                    "geometry": LineString(np.column_stack([g.x[sl], g.y[sl]])),
                })
    return gpd.GeoDataFrame(recs, geometry="geometry", crs=crs)


def polygons(network: list[gl.Gully], min_depth: float, crs: str) -> gpd.GeoDataFrame:
    """Gully outlines (rim to rim) per gully: union of segment buffers where depth ≥ min_depth.

    Parameters
    ----------
    network : list of Gully
        The network.
    min_depth : float
        Least depth (m) at both ends of a segment that is kept.
    crs : str
        Site CRS.

    Returns
    -------
    GeoDataFrame
        One polygon per gully that has a kept segment: ``gully_id, kind, area_m2``.
    """
    recs = []
    for g in network:
        ok = (g.depth[:-1] >= min_depth) & (g.depth[1:] >= min_depth)
        if not ok.any():
            continue
        idx = np.nonzero(ok)[0]
        lines = shapely.linestrings(np.stack([np.column_stack([g.x[idx], g.y[idx]]), np.column_stack([g.x[idx + 1], g.y[idx + 1]])], axis=1))
        half = 0.25 * (g.width[idx] + g.width[idx + 1])
        poly = shapely.union_all(shapely.buffer(lines, half, quad_segs=4))
        recs.append({"gully_id": g.gully_id, "kind": g.kind, "area_m2": float(poly.area), "geometry": poly})
    return gpd.GeoDataFrame(recs, geometry="geometry", crs=crs)


def heads(network: list[gl.Gully], crs: str, retreat: dict) -> gpd.GeoDataFrame:
    """True gully heads (not the wadi): id, kind, bank, headcut, retreat since epoch 1.

    Parameters
    ----------
    network : list of Gully
        The network.
    crs : str
        Site CRS.
    retreat : dict
        Retreat (m) per gully id; missing ids get 0.

    Returns
    -------
    GeoDataFrame
        One point per head: ``gully_id, kind, bank, headcut, retreat_m, end``.
    """
    recs = [{"gully_id": g.gully_id, "kind": g.kind, "bank": g.bank, "headcut": bool(g.headcut),
             "retreat_m": float(retreat.get(g.gully_id, 0.0)), "end": g.end_reason, "geometry": Point(g.x[0], g.y[0])}
            for g in network if g.kind != "wadi"]
    return gpd.GeoDataFrame(recs, geometry="geometry", crs=crs) if recs else gpd.GeoDataFrame(
        {"gully_id": []}, geometry=[], crs=crs)

