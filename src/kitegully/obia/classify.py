"""Object-based classification: segment means of ExG against a threshold, polygons.

Class codes used throughout the stage: 0 = grass, 1 = eroded, 255 = no data.
"""

from __future__ import annotations

import geopandas as gpd
import numpy as np
import rasterio.features
from affine import Affine
from scipy import ndimage
from shapely.geometry import shape

GRASS = 0
ERODED = 1
NODATA = 255
CLASS_NAMES = {GRASS: "grass", ERODED: "eroded"}


def segment_means(values: np.ndarray, segments: np.ndarray, n_segments: int) -> np.ndarray:
    """Mean of the finite ``values`` in each segment 1..n (index 0 unused, NaN if empty). O(N).

    Parameters
    ----------
    values : ndarray (H, W)
        Values to average, e.g. ExG; NaN cells are left out.
    segments : ndarray (H, W) int
        Segment labels, 0 = no segment.
    n_segments : int
        Highest segment label.

    Returns
    -------
    ndarray (n_segments + 1,) float64
        Mean of each segment, indexed by label.
    """
    lab = segments.ravel()
    v = values.ravel().astype(np.float64)
    ok = (lab > 0) & np.isfinite(v)
    sums = np.bincount(lab[ok], weights=v[ok], minlength=n_segments + 1)
    counts = np.bincount(lab[ok], minlength=n_segments + 1)
    with np.errstate(invalid="ignore", divide="ignore"):
        means = sums / counts
    means[counts == 0] = np.nan
    return means


def classify_segments(means: np.ndarray, segments: np.ndarray, threshold: float | None, unimodal_class: int = GRASS) -> np.ndarray:
    """Class raster: grass where the segment mean ExG > threshold, eroded otherwise.

    With ``threshold`` None (histogram not bimodal) every segment gets ``unimodal_class``.
    Cells outside all segments (label 0) are NODATA.

    Parameters
    ----------
    means : ndarray (n_segments + 1,)
        Segment mean ExG indexed by label (:func:`segment_means`); NaN segments become NODATA.
    segments : ndarray (H, W) int
        Segment labels, 0 = no segment.
    threshold : float or None
        ExG threshold between eroded and grass.
    unimodal_class : int
        Class of every segment when ``threshold`` is None.

    Returns
    -------
    ndarray (H, W) uint8
        Class codes (GRASS, ERODED, NODATA).
    """
    if threshold is None:
        seg_class = np.full(means.shape, unimodal_class, dtype=np.uint8)
    else:
        seg_class = np.where(means > threshold, GRASS, ERODED).astype(np.uint8)
    seg_class[0] = NODATA
    seg_class[np.isnan(means) & (np.arange(means.size) > 0)] = NODATA
    return seg_class[segments]


def remove_small_eroded(classes: np.ndarray, cell: float, min_area_m2: float) -> np.ndarray:
    """Turn 8-connected eroded pieces smaller than ``min_area_m2`` into grass (0 = off).

    Parameters
    ----------
    classes : ndarray (H, W) uint8
        Class codes.
    cell : float
        Cell size (m).
    min_area_m2 : float
        Smallest eroded piece kept (m²).

    Returns
    -------
    ndarray (H, W) uint8
        Class codes; ``classes`` itself when ``min_area_m2`` is 0 or less or no cell is eroded, else a copy.
    """
    if min_area_m2 <= 0:
        return classes
    eroded = classes == ERODED
    lab, n = ndimage.label(eroded, structure=np.ones((3, 3), dtype=bool))
    if n == 0:
        return classes
    area = np.bincount(lab.ravel(), minlength=n + 1) * cell * cell
    small = area < min_area_m2
    small[0] = False
    out = classes.copy()
    out[small[lab]] = GRASS
    return out


def eroded_polygons(classes: np.ndarray, transform: Affine, crs: str, scene: str | None = None) -> gpd.GeoDataFrame:
    """Polygons of the eroded class with area (m²); one row per connected piece.

    Columns: ``scene`` (if given), ``piece_id``, ``class``, ``area_m2``, geometry.

    Parameters
    ----------
    classes : ndarray (H, W) uint8
        Class codes.
    transform : Affine
        Georeferencing of the class raster.
    crs : str
        CRS of the polygons.
    scene : str or None
        Scene name for the ``scene`` column.

    Returns
    -------
    GeoDataFrame
        Eroded pieces, 8-connected.
    """
    mask = classes == ERODED
    geoms = [shape(g) for g, v in rasterio.features.shapes(mask.astype(np.uint8), mask=mask, transform=transform, connectivity=8) if v == 1]
    gdf = gpd.GeoDataFrame({"piece_id": np.arange(1, len(geoms) + 1, dtype=np.int32), "class": "eroded"}, geometry=geoms, crs=crs)
    gdf["area_m2"] = gdf.geometry.area
    if scene is not None:
        gdf.insert(0, "scene", scene)
    return gdf
