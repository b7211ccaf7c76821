"""Figures of the gully stage: section view (Fig. 4 style) and validation map (Fig. 9b style)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import scipy.ndimage as ndi
from matplotlib.colors import ListedColormap
from shapely.geometry.base import BaseGeometry

from kitegully.gully.network import GullyNetwork
from kitegully.io.figures import map_axes, new_figure
from kitegully.io.raster import GridSpec
from kitegully.terrain.shading import hillshade

if TYPE_CHECKING:
    from matplotlib.figure import Figure


def pick_section(net: GullyNetwork, depth: np.ndarray, gully: np.ndarray, grid: GridSpec, half_length_m: float) -> tuple[float, float, float, float]:
    """A transect across the deepest mapped network cell, perpendicular to the local flow.

    Falls back to a north-south transect through the grid centre when no network cell
    is mapped. Returns (x0, y0, x1, y1) in map units.

    Parameters
    ----------
    net : GullyNetwork
        The traced network.
    depth : ndarray (H, W)
        Depth map (m).
    gully : ndarray (H, W) bool
        The gully map.
    grid : GridSpec
        The grid.
    half_length_m : float
        Half the transect's length (m); only cells at least this far from the grid edge are picked.

    Returns
    -------
    x0, y0, x1, y1 : float
        Ends of the transect (m).
    """
    h, w = grid.height, grid.width
    rad = half_length_m / grid.cell
    cells = net.cells
    r, c = grid.unravel(cells)
    ok = gully.ravel()[cells] & (r > rad) & (r < h - rad) & (c > rad) & (c < w - rad) if cells.size else np.zeros(0, bool)
    if not ok.any():
        xc, yc = grid.centre
        return xc, yc + half_length_m, xc, yc - half_length_m
    cand = np.flatnonzero(ok)
    k = cand[np.argmax(depth.ravel()[cells[cand]])]
    # flow direction from ~10 cells downstream (or upstream at the end of a path)
    j = k
    for _ in range(10):
        if net.pos_down[j] < 0:
            break
        j = net.pos_down[j]
    dr, dc = float(r[j] - r[k]), float(c[j] - c[k])
    if dr == 0 and dc == 0:
        dr, dc = 1.0, 0.0
    n = np.hypot(dr, dc)
    # perpendicular in (row, col) → map: x = col, y = -row
    px, py = -dr / n, -dc / n  # unit vector perpendicular to (dc, -dr)
    xc, yc = grid.xy(r[k], c[k])
    return xc - px * half_length_m, yc - py * half_length_m, xc + px * half_length_m, yc + py * half_length_m


def _sample(a: np.ndarray, grid: GridSpec, x: np.ndarray, y: np.ndarray, order: int) -> np.ndarray:
    row, col = grid.rowcol(x, y)
    return ndi.map_coordinates(np.asarray(a, dtype=np.float64), [row, col], order=order, mode="nearest", prefilter=False)


def section_figure(
    dem: np.ndarray,
    smoothed: np.ndarray,
    depth: np.ndarray,
    gully: np.ndarray,
    grid: GridSpec,
    line: tuple[float, float, float, float],
    sigma_m: float,
    threshold_m: float,
) -> Figure:
    """Four stacked panels along a transect: kernel, DEM vs smoothed, depth, detected cells.

    Parameters
    ----------
    dem, smoothed, depth : ndarray (H, W)
        The DEM, its smoothed surface and the depth map (m), sampled bilinearly every half cell.
    gully : ndarray (H, W) bool
        The gully map, sampled at the nearest cell.
    grid : GridSpec
        The grid.
    line : tuple of float
        The transect ``(x0, y0, x1, y1)`` (m), e.g. from :func:`pick_section`.
    sigma_m : float
        σ of the Gaussian (m), drawn in the kernel panel.
    threshold_m : float
        Depth threshold (m), drawn in the depth panel.

    Returns
    -------
    Figure
        The matplotlib figure.
    """
    x0, y0, x1, y1 = line
    length = float(np.hypot(x1 - x0, y1 - y0))
    s = np.arange(0.0, length + 1e-9, grid.cell / 2)
    x = x0 + (x1 - x0) * s / length
    y = y0 + (y1 - y0) * s / length
    z = _sample(dem, grid, x, y, 1)
    zs = _sample(smoothed, grid, x, y, 1)
    d = _sample(depth, grid, x, y, 1)
    g = _sample(gully.astype(np.float64), grid, x, y, 0) > 0.5
    fig, ax = new_figure(4, 1, figsize=(6.5, 8.0), sharex=True)
    mid = length / 2
    kern = np.exp(-0.5 * ((s - mid) / sigma_m) ** 2) / (sigma_m * np.sqrt(2 * np.pi))
    ax[0].plot(s, kern, color="k")
    ax[0].set_ylabel("kernel weight (1/m)")
    ax[0].set_title(f"(a) Gaussian kernel, σ = {sigma_m:g} m")
    ax[1].plot(s, z, color="saddlebrown", label="DEM")
    ax[1].plot(s, zs, color="tab:blue", label=f"smoothed (σ = {sigma_m:g} m)")
    ax[1].set_ylabel("elevation (m)")
    ax[1].set_title("(b) original and smoothed profile")
    ax[1].legend(loc="best")
    ax[2].plot(s, d, color="tab:purple", label="depth = smoothed − DEM")
    ax[2].axhline(threshold_m, color="tab:red", ls="--", label=f"threshold {threshold_m:g} m")
    ax[2].axhline(0, color="0.5", lw=0.5)
    ax[2].set_ylabel("depth (m)")
    ax[2].set_title("(c) depth")
    ax[2].legend(loc="best")
    ax[3].fill_between(s, 0, np.where(g, d, 0), step="mid", color="tab:orange", label="mapped gully")
    ax[3].plot(s, d, color="tab:purple", lw=0.8)
    ax[3].set_ylabel("depth (m)")
    ax[3].set_xlabel("distance along the transect (m)")
    ax[3].set_title("(d) detected gully cells")
    ax[3].legend(loc="best")
    fig.tight_layout()
    return fig


def validation_map(
    dem: np.ndarray,
    gully: np.ndarray,
    grid: GridSpec,
    pieces: dict[str, BaseGeometry],
    tolerance_m: float,
    max_pixels: int = 1500,
) -> Figure:
    """Fig. 9b style map: hillshade, mapped gullies, good fit / false negative / false positive lines.

    Colours as in the paper's Fig. 9b: yellow good fit, thick black false positives, blue
    false negatives, green reference lines left out of the score (``pieces["not_scored"]``,
    outside the catchment or fed only by heads off the DEM).

    Parameters
    ----------
    dem : ndarray (H, W)
        The DEM (m), shown as a hillshade.
    gully : ndarray (H, W) bool
        The gully map.
    grid : GridSpec
        The grid.
    pieces : dict of str to geometry
        Lines by category (:func:`kitegully.evaluate.network.validation_geometries`); missing keys are not drawn.
    tolerance_m : float
        Matching tolerance (m), named in the title.
    max_pixels : int
        The rasters are decimated to at most this many pixels per side.

    Returns
    -------
    Figure
        The matplotlib figure.
    """
    step = max(1, int(np.ceil(max(grid.height, grid.width) / max_pixels)))
    z = dem[::step, ::step]
    hs = hillshade(z, grid.cell * step)
    xmin, ymin, xmax, ymax = grid.bounds
    ext = (xmin, xmin + z.shape[1] * step * grid.cell, ymax - z.shape[0] * step * grid.cell, ymax)  # decimated cells
    fig, ax = new_figure(figsize=(7.0, 7.0 * (ymax - ymin) / max(xmax - xmin, 1e-9) + 0.6))
    ax.imshow(hs, cmap="gray", extent=ext, interpolation="nearest")
    gm = gully[::step, ::step].astype(float)
    gm[gm == 0] = np.nan
    ax.imshow(gm, cmap=ListedColormap(["tab:orange"]), alpha=0.45, extent=ext, interpolation="nearest")
    styles = {
        "not_scored": ("tab:green", 1.2, "reference not scored (head off the DEM / outside catchment)"),
        "good_fit": ("gold", 1.4, "good fit (reference)"),
        "false_negative": ("tab:blue", 1.4, "false negative (reference missed)"),
        "false_positive": ("black", 2.2, "false positive (extracted only)"),
    }
    for key, (color, lw, label) in styles.items():
        geom = pieces.get(key)
        if geom is None:
            continue
        first = True
        for part in getattr(geom, "geoms", [geom]):
            if part.is_empty or part.geom_type not in ("LineString", "LinearRing"):
                for sub in getattr(part, "geoms", []):
                    if sub.geom_type == "LineString":
                        xs, ys = sub.xy
                        ax.plot(xs, ys, color=color, lw=lw, label=label if first else None)
                        first = False
                continue
            xs, ys = part.xy
            ax.plot(xs, ys, color=color, lw=lw, label=label if first else None)
            first = False
    ax.plot([], [], color="tab:orange", lw=6, alpha=0.45, label="mapped gully area")
    map_axes(ax)
    ax.set_title(f"Gully network validation (tolerance {tolerance_m:g} m)")
    # below the map (the tight bounding box takes it in): inside, it hid the gullies of a corner
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=2, fontsize=7, frameon=False)
    return fig
