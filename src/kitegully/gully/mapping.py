"""Final gully map (Fig. 3 k-m): network buffer ∩ depth patches, and gully polygons."""

from __future__ import annotations

import cv2
import geopandas as gpd
import numpy as np
import rasterio.features
import shapely

from kitegully.gully.patches import label_mask
from kitegully.io.raster import GridSpec


def buffer_mask(network: np.ndarray, cell_m: float, buffer_m: float) -> np.ndarray:
    """Cells whose centre lies within ``buffer_m`` of a network cell centre (exact Euclidean distance transform).

    Complexity O(n) (OpenCV's exact distance transform on a byte image).

    Parameters
    ----------
    network : ndarray (H, W) bool
        Network cells.
    cell_m : float
        Cell size (m).
    buffer_m : float
        Buffer distance (m).

    Returns
    -------
    ndarray (H, W) bool
        All False when the network is empty.
    """
    if not network.any():
        return np.zeros(network.shape, dtype=bool)
    src = np.logical_not(network).view(np.uint8)  # 0 on the network, 1 elsewhere (no int64 temporary)
    dist = cv2.distanceTransform(src, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    return dist * cell_m <= buffer_m


def final_map(patch_labels: np.ndarray, buffer: np.ndarray, whole_patches: bool = False) -> np.ndarray:
    """Gully map: patch cells inside the buffer, or ([I] variant) whole patches touching it. O(n).

    Parameters
    ----------
    patch_labels : ndarray (H, W) int
        Depth patch labels, 0 = background.
    buffer : ndarray (H, W) bool
        The network buffer (:func:`buffer_mask`).
    whole_patches : bool
        Keep every patch with a cell inside the buffer whole.

    Returns
    -------
    ndarray (H, W) bool
        The gully map.
    """
    inside = (patch_labels > 0) & buffer
    if not whole_patches:
        return inside
    touched = np.zeros(int(patch_labels.max()) + 1, dtype=bool)
    touched[np.unique(patch_labels[inside])] = True
    touched[0] = False
    return touched[patch_labels]


def gully_polygons(gully: np.ndarray, depth: np.ndarray, grid: GridSpec, connectivity: int = 8) -> gpd.GeoDataFrame:
    """One polygon per connected gully of the map, with depth, area and volume.

    Attributes: ``gully_id``, ``area_m2``, ``volume_m3`` (Σ depth · cell²),
    ``mean_depth_m``, ``max_depth_m``.

    Complexity O(n) for the labels and the polygon tracing.

    Parameters
    ----------
    gully : ndarray (H, W) bool
        The gully map.
    depth : ndarray (H, W)
        Depth map (m); NaN counts as 0.
    grid : GridSpec
        The grid; its CRS is the polygons'.
    connectivity : int
        4 or 8: cell connectivity of a gully.

    Returns
    -------
    GeoDataFrame
        One row per gully, ``gully_id`` from 1.
    """
    labels, n = label_mask(gully, connectivity)
    cell2 = grid.cell**2
    flat = labels.ravel()
    inside = flat > 0
    d = np.nan_to_num(depth.ravel()[inside], nan=0.0).astype(np.float64)
    lab = flat[inside]
    counts = np.bincount(lab, minlength=n + 1)
    vol = np.bincount(lab, weights=d, minlength=n + 1) * cell2
    maxd = np.zeros(n + 1)
    np.maximum.at(maxd, lab, d)
    geoms: dict[int, list] = {}
    if n:
        for geom, value in rasterio.features.shapes(
            labels, mask=labels > 0, transform=grid.transform, connectivity=connectivity
        ):
            geoms.setdefault(int(value), []).append(shapely.geometry.shape(geom))
    ids = np.arange(1, n + 1)
    polys = [shapely.union_all(geoms[i]) if len(geoms[i]) > 1 else geoms[i][0] for i in ids]
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(counts[1:] > 0, vol[1:] / cell2 / counts[1:], np.nan)
    return gpd.GeoDataFrame(
        {
            "gully_id": ids.astype(np.int64),
            "area_m2": counts[1:] * cell2,
            "volume_m3": vol[1:],
            "mean_depth_m": mean,
            "max_depth_m": maxd[1:],
        },
        geometry=gpd.GeoSeries(polys, crs=grid.crs),
        crs=grid.crs,
    )
