"""Synthetic terrains with known gullies for the polygon tests."""

from __future__ import annotations

import numpy as np

from kitegully.io.raster import GridSpec

CRS = "EPSG:32632"


def notch_dem(shape: str = "V", width: float = 4.0, depth: float = 1.5, cell: float = 0.5, nx: int = 160, ny: int = 240,
              long_slope: float = 0.02, cross_slope: float = 0.02, exponent: float = 4.0,
              head_m: float | None = None) -> tuple[np.ndarray, GridSpec, float]:
    """A straight gully along y (running south, downhill) in a plane tilted towards it.

    Section ``D (1 - |d/h|^p)`` for |d| < h = width/2 (p = 1 for V, ``exponent`` for U),
    as the twin carves; the axis on a cell centre. With ``head_m`` the gully starts with a
    headcut that far below the upper (north) edge. Returns (dem, grid, x of the gully axis).
    """
    grid = GridSpec(500000.0, 4000000.0, cell, nx, ny, CRS)
    xs, ys = grid.cell_centres()
    x, y = np.meshgrid(xs, ys)
    xc = float(xs[nx // 2])
    d = np.abs(x - xc)
    z = 100.0 + long_slope * (y - ys.min()) + cross_slope * d
    p = 1.0 if shape == "V" else exponent
    h = 0.5 * width
    carve = np.where(d < h, depth * (1.0 - (d / h) ** p), 0.0)
    if head_m is not None:
        carve[y > ys.max() - head_m] = 0.0
    return (z - carve).astype(np.float32), grid, float(xc)


def true_area(shape: str, width: float, depth: float, exponent: float = 4.0) -> float:
    """Cross-sectional area of the notch below its (level) rim: W D p / (p + 1)."""
    p = 1.0 if shape == "V" else exponent
    return width * depth * p / (p + 1.0)
