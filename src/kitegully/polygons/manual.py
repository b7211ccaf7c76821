"""Simulated manual operators digitising gully outlines on the shaded DEM (twin evaluation only).

The paper compares its polygons with nine outlines digitised by different geomorphologists
on shaded reliefs (Höfle et al. 2013 sect. 4.4, Table 1). A twin has no operators, so each
is simulated from the true gully outlines with its own habits, drawn once per operator
from the ranges in the config (seeded by :func:`kitegully.seeds.rng_for`):

1. **Visibility**: gullies whose true maximum depth is below the operator's
   ``min_visible_depth_m`` do not show on the shading and are not digitised.
2. **Edge bias**: the whole outline is offset outward (> 0, the operator includes the
   upper slopes) or inward (< 0) by a normal draw of SD ``edge_bias_sd_m``.
3. **Edge placement error**: every boundary vertex (densified to 1 m) moves along the
   outline normal by a correlated error (Gaussian-smoothed white noise of correlation
   length ``edge_noise_wavelength_m``) of SD drawn in ``edge_noise_sd_m``.
4. **Generalisation**: Douglas-Peucker simplification with a tolerance drawn in
   ``generalisation_m`` (how coarsely the operator clicks).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping

import geopandas as gpd
import numpy as np
import pandas as pd
import scipy.ndimage as ndi
import shapely

from kitegully.config import config_section
from kitegully.seeds import rng_for


@dataclass(frozen=True)
class OperatorParams:
    """Habits of the simulated operators (``polygons.evaluation.operators``).

    Attributes
    ----------
    count : int
        Number of operators [P 9].
    min_visible_depth_m : tuple of float
        Range of the shallowest gully an operator sees on the shading (m) [I].
    edge_bias_sd_m : float
        SD of the per-operator outward offset of the outline (m) [I].
    edge_noise_sd_m : tuple of float
        Range of the per-operator SD of the edge placement error (m) [I].
    edge_noise_wavelength_m : float
        Correlation length of the edge placement error along the outline (m) [I].
    generalisation_m : tuple of float
        Range of the per-operator Douglas-Peucker tolerance (m) [I].
    """

    count: int = 9
    min_visible_depth_m: tuple = (0.2, 0.5)
    edge_bias_sd_m: float = 0.5
    edge_noise_sd_m: tuple = (0.2, 0.6)
    edge_noise_wavelength_m: float = 10.0
    generalisation_m: tuple = (0.25, 1.5)

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any]) -> "OperatorParams":
        """Build from ``polygons.evaluation.operators``."""
        cfg = config_section(cfg, "polygons.evaluation.operators", ["count", "min_visible_depth_m", "edge_bias_sd_m", "edge_noise_sd_m",
                                                                     "edge_noise_wavelength_m", "generalisation_m"])
        return cls(count=int(cfg["count"]), min_visible_depth_m=tuple(cfg["min_visible_depth_m"]), edge_bias_sd_m=float(cfg["edge_bias_sd_m"]),
                   edge_noise_sd_m=tuple(cfg["edge_noise_sd_m"]), edge_noise_wavelength_m=float(cfg["edge_noise_wavelength_m"]),
                   generalisation_m=tuple(cfg["generalisation_m"]))


def _perturb_ring(ring: shapely.LinearRing, sd: float, wavelength: float, rng: np.random.Generator) -> np.ndarray:
    L = ring.length
    n = max(int(np.ceil(L / 1.0)), 8)
    s = np.linspace(0.0, L, n, endpoint=False)
    pts = shapely.line_interpolate_point(shapely.LineString(ring.coords), s)
    xy = np.column_stack([shapely.get_x(pts), shapely.get_y(pts)])
    tang = np.roll(xy, -1, axis=0) - np.roll(xy, 1, axis=0)
    tn = np.hypot(tang[:, 0], tang[:, 1])
    tn[tn == 0] = 1.0
    normal = np.column_stack([tang[:, 1], -tang[:, 0]]) / tn[:, None]
    e = rng.standard_normal(n)
    if sd > 0:
        # smoothing at most over a sixth of the ring, so a small outline still wobbles
        e = ndi.gaussian_filter1d(e, min(wavelength / (L / n) / 2.0, n / 6.0), mode="wrap")
        e *= sd / e.std()
    else:
        e[:] = 0.0
    return xy + normal * e[:, None]


def operator_outlines(truth: gpd.GeoDataFrame, max_depth: Mapping[int, float], params: OperatorParams, seed: int) -> gpd.GeoDataFrame:
    """One digitised outline set per operator.

    Parameters
    ----------
    truth : GeoDataFrame
        True gully polygons with ``gully_id``.
    max_depth : mapping
        True maximum depth (m) per ``gully_id``.
    params : OperatorParams
    seed : int
        Master seed.

    Returns
    -------
    GeoDataFrame
        ``operator`` (1..n), habits drawn (``min_visible_depth_m``, ``edge_bias_m``,
        ``edge_noise_sd_m``, ``generalisation_m``), ``area_m2`` and the operator's
        (multi)polygon.
    """
    recs = []
    for k in range(1, params.count + 1):
        rng = rng_for(seed, "polygons", "operator", str(k))
        vis = rng.uniform(*params.min_visible_depth_m)
        bias = rng.normal(0.0, params.edge_bias_sd_m)
        sd = rng.uniform(*params.edge_noise_sd_m)
        tol = rng.uniform(*params.generalisation_m)
        parts = []
        for gid, geom in zip(truth["gully_id"], truth.geometry):
            if max_depth.get(int(gid), 0.0) < vis:
                continue
            g = geom.buffer(bias) if bias else geom
            for poly in getattr(g, "geoms", [g]):
                if poly.is_empty or poly.geom_type != "Polygon":
                    continue
                ext = _perturb_ring(poly.exterior, sd, params.edge_noise_wavelength_m, rng)
                p = shapely.Polygon(ext).buffer(0).simplify(tol)
                if not p.is_empty:
                    parts.append(p)
        geom = shapely.union_all(parts) if parts else shapely.Polygon()
        recs.append({"operator": k, "min_visible_depth_m": vis, "edge_bias_m": bias, "edge_noise_sd_m": sd,
                     "generalisation_m": tol, "area_m2": geom.area, "geometry": geom})
    return gpd.GeoDataFrame(recs, geometry="geometry", crs=truth.crs)


def habits_table(ops: gpd.GeoDataFrame) -> pd.DataFrame:
    """The drawn habits and digitised area per operator."""
    return pd.DataFrame(ops.drop(columns="geometry"))
