"""Seed cells for region growing: minima of local feature variance.

Our reading [I] of SAGA's "Seed Generation" with band-width smoothing, which Mayr et
al. (2016) used with a band width of 15 cells:

1. block-average each feature to ``bandwidth`` x the cell size, then interpolate it back
   to the full grid with a cubic B-spline (a smooth version of the feature);
2. in every 3x3 window compute the variance of the nine feature-space (Euclidean)
   distances of the smoothed feature vectors to the window centroid (METHODS.md 2.2.5;
   SAGA's variance grid is the variance of such distances too);
3. a seed is a cell whose variance is <= that of all 8 neighbours; a connected plateau of
   such cells gives one seed (its first cell in row-major order).

Seeds therefore sit in the flattest parts of the smoothed feature field, roughly one per
band-width block, so segments stay small compared with the eroded patches.
Cost: O(N k) for N cells and k features.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage


def _bandwidth_smooth(layer: np.ndarray, bandwidth: int) -> np.ndarray:
    rows, cols = layer.shape
    br = max(1, int(np.ceil(rows / bandwidth)))
    bc = max(1, int(np.ceil(cols / bandwidth)))
    pad_r = br * bandwidth - rows
    pad_c = bc * bandwidth - cols
    padded = np.pad(layer, ((0, pad_r), (0, pad_c)), mode="edge")
    coarse = padded.reshape(br, bandwidth, bc, bandwidth).mean(axis=(1, 3))
    if br < 2 or bc < 2:
        return np.broadcast_to(coarse.mean(), layer.shape).astype(np.float32)
    # block centres sit at (i + 0.5) * bandwidth - 0.5 in full-grid cell coordinates
    r = (np.arange(rows) + 0.5) / bandwidth - 0.5
    c = (np.arange(cols) + 0.5) / bandwidth - 0.5
    rr, cc = np.meshgrid(r, c, indexing="ij")
    return ndimage.map_coordinates(coarse, [rr, cc], order=3, mode="nearest").astype(np.float32)


def local_feature_variance(features: np.ndarray, bandwidth: int) -> np.ndarray:
    """Variance of the distances of the band-width-smoothed feature vectors to their 3x3 centroid.

    The grid border is extended by replication.  Memory: the smoothed stack plus a few
    N-sized arrays (the nine distances are accumulated, not stored).  O(9 N k).
    """
    rows, cols, k = features.shape
    smooth = np.stack([_bandwidth_smooth(features[..., j], bandwidth) for j in range(k)], axis=-1).astype(np.float64)
    centroid = np.stack([ndimage.uniform_filter(smooth[..., j], size=3, mode="nearest") for j in range(k)], axis=-1)
    padded = np.pad(smooth, ((1, 1), (1, 1), (0, 0)), mode="edge")
    s1 = np.zeros((rows, cols))
    s2 = np.zeros((rows, cols))
    for dr in (0, 1, 2):
        for dc in (0, 1, 2):
            d = np.sqrt(np.sum((padded[dr:dr + rows, dc:dc + cols] - centroid) ** 2, axis=-1))
            s1 += d
            s2 += d * d
    return np.maximum(s2 / 9.0 - (s1 / 9.0) ** 2, 0.0)


def generate_seeds(features: np.ndarray, valid: np.ndarray, bandwidth: int) -> np.ndarray:
    """Seed cells as an int32 raster: 1..n at seeds, 0 elsewhere.

    Parameters
    ----------
    features
        (rows, cols, k) normalised features; invalid cells are ignored.
    valid
        Boolean mask of cells that may be seeds (and may be grown into).
    bandwidth
        Band width in cells (Mayr et al.: 15).
    """
    if bandwidth < 1:
        raise ValueError(f"seed band width must be >= 1 cell, got {bandwidth}")
    var = local_feature_variance(features, bandwidth)
    var[~valid] = np.inf
    neigh_min = ndimage.minimum_filter(var, size=3, mode="nearest")
    is_min = (var <= neigh_min) & valid
    plateaus, n = ndimage.label(is_min, structure=np.ones((3, 3), dtype=bool))
    seeds = np.zeros(var.shape, dtype=np.int32)
    if n == 0:
        return seeds
    flat = plateaus.ravel()
    order = np.flatnonzero(flat)
    _, first = np.unique(flat[order], return_index=True)
    cells = order[first]
    seeds.ravel()[cells] = np.arange(1, len(cells) + 1, dtype=np.int32)
    return seeds
