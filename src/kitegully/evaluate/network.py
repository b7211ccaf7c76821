"""Validation of an extracted gully network and gully map (paper 000 sect. 2.6.2).

Line lengths follow Thommeret et al. (2010), with every percentage relative to the
reference length ``L_ref``:

* good fit: reference length inside the extracted-network domain;
* false negative: reference length outside it (good fit + FN = L_ref);
* false positive: extracted length outside the reference domain.

[I] The "domain" of a network is a buffer of τ around it (default 5 m). Area scores
compare a gully map with truth polygons cell by cell.
"""

from __future__ import annotations

from collections.abc import Iterable

import geopandas as gpd
import numpy as np
import pandas as pd
import rasterio.features
import shapely
import shapely.geometry
from shapely.geometry.base import BaseGeometry

from kitegully.io.raster import GridSpec

CATEGORIES = ("reference", "good_fit", "false_positive", "false_negative")


def _lines(geoms: gpd.GeoDataFrame | gpd.GeoSeries | Iterable[BaseGeometry]) -> BaseGeometry:
    if isinstance(geoms, gpd.GeoDataFrame):
        geoms = geoms.geometry
    arr = [g for g in geoms if g is not None and not g.is_empty]
    return shapely.union_all(arr) if arr else shapely.GeometryCollection()


def network_validation(
    reference: gpd.GeoDataFrame | gpd.GeoSeries | Iterable[BaseGeometry],
    extracted: gpd.GeoDataFrame | gpd.GeoSeries | Iterable[BaseGeometry],
    tolerance_m: float,
    domain: BaseGeometry | None = None,
) -> pd.DataFrame:
    """Good fit, false positive and false negative lengths of an extracted network.

    Parameters
    ----------
    reference, extracted : lines
        The reference (field) network and the extracted network, same CRS (m).
    tolerance_m : float
        Matching tolerance τ (m): the domain of a network is its buffer of τ.
    domain : Polygon, optional
        Area where the comparison is made (e.g. the DEM footprint); both networks are
        clipped to it first.

    Returns
    -------
    DataFrame
        Columns ``category, length_m, percent``, rows ``reference, good_fit,
        false_positive, false_negative``; ``percent`` is relative to the reference length
        (NaN when it is 0).

    Notes
    -----
    Complexity O((m + k) log(m + k)) for m, k line vertices (GEOS overlay).
    """
    if tolerance_m < 0:
        raise ValueError(f"tolerance must be >= 0, got {tolerance_m}")
    ref = _lines(reference)
    ext = _lines(extracted)
    if domain is not None:
        ref = ref.intersection(domain)
        ext = ext.intersection(domain)
    l_ref = ref.length
    if ext.is_empty:
        good = 0.0
    else:
        good = ref.intersection(ext.buffer(tolerance_m)).length
    fp = ext.length if ref.is_empty else ext.difference(ref.buffer(tolerance_m)).length
    fn = l_ref - good
    lengths = np.array([l_ref, good, fp, fn], dtype=float)
    percent = lengths / l_ref * 100.0 if l_ref > 0 else np.full(4, np.nan)
    return pd.DataFrame({"category": list(CATEGORIES), "length_m": lengths, "percent": percent})


def validation_geometries(
    reference: gpd.GeoDataFrame | gpd.GeoSeries | Iterable[BaseGeometry],
    extracted: gpd.GeoDataFrame | gpd.GeoSeries | Iterable[BaseGeometry],
    tolerance_m: float,
    domain: BaseGeometry | None = None,
) -> dict[str, BaseGeometry]:
    """The pieces behind :func:`network_validation`, for maps: ``good_fit``,
    ``false_negative`` (parts of the reference) and ``false_positive`` (part of the
    extracted network)."""
    ref = _lines(reference)
    ext = _lines(extracted)
    if domain is not None:
        ref = ref.intersection(domain)
        ext = ext.intersection(domain)
    ext_dom = ext.buffer(tolerance_m) if not ext.is_empty else shapely.GeometryCollection()
    ref_dom = ref.buffer(tolerance_m) if not ref.is_empty else shapely.GeometryCollection()
    return {
        "good_fit": ref.intersection(ext_dom),
        "false_negative": ref.difference(ext_dom),
        "false_positive": ext.difference(ref_dom),
    }


def rasterize_polygons(polygons: gpd.GeoDataFrame | Iterable[BaseGeometry], grid: GridSpec) -> np.ndarray:
    """Boolean mask of the cells whose centre falls in any polygon. O(n)."""
    geoms = list(polygons.geometry if isinstance(polygons, gpd.GeoDataFrame) else polygons)
    geoms = [g for g in geoms if g is not None and not g.is_empty]
    if not geoms:
        return np.zeros((grid.height, grid.width), dtype=bool)
    out = rasterio.features.rasterize(
        [(g, 1) for g in geoms], out_shape=(grid.height, grid.width), transform=grid.transform, fill=0, dtype="uint8"
    )
    return out.astype(bool)


def footprint(valid: np.ndarray, grid: GridSpec) -> BaseGeometry:
    """Polygon of the valid cells of a raster (the DEM footprint). O(n)."""
    valid = np.asarray(valid, dtype=np.uint8)
    polys = [shapely.geometry.shape(g) for g, v in rasterio.features.shapes(valid, mask=valid > 0, transform=grid.transform) if v]
    return shapely.union_all(polys) if polys else shapely.Polygon()


def area_scores(predicted: np.ndarray, truth: np.ndarray, cell_m: float) -> dict[str, float]:
    """Cell-wise precision, recall and IoU of a predicted gully mask against the truth mask.

    Returns a dict with ``predicted_area_m2``, ``truth_area_m2``, ``intersection_m2``,
    ``precision``, ``recall``, ``iou`` (NaN where a denominator is 0).
    """
    predicted = np.asarray(predicted, dtype=bool)
    truth = np.asarray(truth, dtype=bool)
    if predicted.shape != truth.shape:
        raise ValueError(f"mask shapes differ: {predicted.shape} vs {truth.shape}")
    a = cell_m**2
    tp = float(np.count_nonzero(predicted & truth)) * a
    p = float(np.count_nonzero(predicted)) * a
    t = float(np.count_nonzero(truth)) * a
    union = p + t - tp
    return {
        "predicted_area_m2": p,
        "truth_area_m2": t,
        "intersection_m2": tp,
        "precision": tp / p if p else float("nan"),
        "recall": tp / t if t else float("nan"),
        "iou": tp / union if union else float("nan"),
    }
