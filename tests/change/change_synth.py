"""Synthetic DEM pairs for the change-stage tests: known terrain, pit, mound, noise, shift, tilt."""

from __future__ import annotations

import numpy as np

from kitegully.io.raster import GridSpec, Raster
from kitegully.seeds import rng_for

CRS = "EPSG:32632"


def grid(n: int = 200, cell: float = 0.5, x0: float = 500000.0, y0: float = 4100000.0) -> GridSpec:
    return GridSpec(x0, y0, cell, n, n, CRS)


def terrain(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Hilly analytic surface (m): slopes in every direction, relief of a few metres."""
    return (100.0 + 0.05 * (x - 500000.0) + 2.0 * np.sin((x - 500000.0) / 9.0) * np.cos((y - 4100000.0) / 7.0)
            + 1.5 * np.sin((y - 4100000.0) / 11.0 + 0.3))


def xy(g: GridSpec) -> tuple[np.ndarray, np.ndarray]:
    xs, ys = g.cell_centres()
    return np.meshgrid(xs, ys)


def bump(g: GridSpec, cx: float, cy: float, radius: float, height: float) -> np.ndarray:
    """Cosine bump (mound if height > 0, pit if < 0) of a given radius (m)."""
    X, Y = xy(g)
    r = np.hypot(X - (g.x0 + cx), Y - (g.y0 - cy))
    return np.where(r < radius, height * 0.5 * (1 + np.cos(np.pi * r / radius)), 0.0)


def noise(g: GridSpec, sd: float, name: str, seed: int = 1) -> np.ndarray:
    return sd * rng_for(seed, "test", name).standard_normal((g.height, g.width))


def pair(sd: float = 0.05, seed: int = 1):
    """(grid, z1, z2, change): pit of −0.8 m (radius 8 m) and mound of +0.5 m (radius 6 m)."""
    g = grid()
    X, Y = xy(g)
    z = terrain(X, Y)
    change = bump(g, 30.0, 30.0, 8.0, -0.8) + bump(g, 70.0, 65.0, 6.0, 0.5)
    z1 = (z + noise(g, sd, "e1", seed)).astype(np.float32)
    z2 = (z + change + noise(g, sd, "e2", seed)).astype(np.float32)
    return g, z1, z2, change


def write(path, data: np.ndarray, g: GridSpec, nodata=None) -> str:
    Raster(data.astype(np.float32), g).write(path) if nodata is None else _write_raw(path, data, g, nodata)
    return str(path)


def _write_raw(path, data, g, nodata):
    import rasterio
    prof = dict(driver="GTiff", width=g.width, height=g.height, count=1, dtype="float32", crs=g.crs, transform=g.transform)
    if nodata != "none":
        prof["nodata"] = nodata
    with rasterio.open(path, "w", **prof) as dst:
        dst.write(data.astype(np.float32), 1)
