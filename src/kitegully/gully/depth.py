"""Depth map (Feurer et al. 2018, Fig. 3 a-d): Gaussian-smoothed DEM minus the DEM."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from kitegully.terrain.smoothing import gaussian_smooth_fft

if TYPE_CHECKING:
    from kitegully.terrain.tiled_fill import Tile


def depth_map(
    z: np.ndarray,
    cell_m: float,
    sigma_m: float,
    truncate: float = 4.0,
    workers: int = 1,
) -> tuple[np.ndarray, np.ndarray]:
    """Smoothed surface ``Zs`` and depth ``D = Zs − Z`` (positive below the smoothed surface).

    Parameters
    ----------
    z : ndarray (H, W)
        DEM (m), NaN nodata.
    cell_m : float
        Cell size (m).
    sigma_m : float
        Standard deviation of the Gaussian (m); the paper uses 10 m (2σ = widest gully).
    truncate : float
        Kernel radius and zero padding in σ.
    workers : int
        FFT threads.

    Returns
    -------
    smoothed, depth : ndarray (H, W) float32
        ``depth`` is NaN where ``z`` is NaN.

    Notes
    -----
    Complexity O(n log n); see :func:`kitegully.terrain.smoothing.gaussian_smooth_fft`.
    """
    smoothed = gaussian_smooth_fft(z, sigma_m / cell_m, truncate=truncate, workers=workers)
    depth = smoothed - np.asarray(z, dtype=np.float32)
    return smoothed, depth


def depth_halo_cells(cell_m: float, sigma_m: float, truncate: float = 4.0) -> int:
    """Overlap (cells) a depth-map tile needs to equal the whole-DEM depth map.

    The kernel radius ``ceil(truncate·σ/cell)`` plus one cell for the edge correction's
    gradient (:func:`kitegully.terrain.smoothing.gaussian_smooth_fft`, ``linear_edges``).

    Parameters
    ----------
    cell_m : float
        Cell size (m).
    sigma_m : float
        Standard deviation of the Gaussian (m).
    truncate : float
        Kernel radius in σ.

    Returns
    -------
    int
        Overlap (cells).
    """
    return int(np.ceil(truncate * sigma_m / cell_m)) + 1


def depth_map_tile(
    path: str,
    tile: Tile,
    cell_m: float,
    sigma_m: float,
    truncate: float = 4.0,
    workers: int = 1,
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`depth_map` of one tile of a DEM file, read with the overlap it needs.

    Parameters
    ----------
    path : str
        The DEM GeoTIFF.
    tile : kitegully.terrain.tiled_fill.Tile
        The tile's window.
    cell_m, sigma_m, truncate, workers
        As :func:`depth_map`.

    Returns
    -------
    smoothed, depth : ndarray (tile.h, tile.w) float32

    Notes
    -----
    Every output cell depends only on DEM cells within :func:`depth_halo_cells`, and the
    outside of the DEM reads as nodata in both cases, so the tile equals the whole-DEM
    result up to float32 rounding of the FFT sums (they are taken relative to the mean
    elevation of the window, not of the DEM): differences of ~1e-5 m, measured by
    ``benchmarks/tiled_rules_check.py``. Memory and time O((tile + 2·halo)²).
    """
    from kitegully.terrain.tiled_fill import read_tile_with_halo

    halo = depth_halo_cells(cell_m, sigma_m, truncate)
    z = read_tile_with_halo(path, tile, halo).astype(np.float32)
    core = (slice(halo, halo + tile.h), slice(halo, halo + tile.w))
    if not np.isfinite(z).any():  # nothing within reach: the whole-DEM smoothing gives NaN here too
        nan = np.full((tile.h, tile.w), np.nan, dtype=np.float32)
        return nan, nan.copy()
    smoothed, depth = depth_map(z, cell_m, sigma_m, truncate, workers)
    return smoothed[core], depth[core]
