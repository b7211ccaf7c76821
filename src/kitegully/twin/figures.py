"""Report figures of the twin: hillshade with gullies, land cover, site overview."""

from __future__ import annotations

from pathlib import Path

import geopandas as gpd
import numpy as np
import pandas as pd
import rasterio
from matplotlib.colors import BoundaryNorm, ListedColormap
from matplotlib.patches import Patch

from kitegully.io.figures import map_axes, new_figure, save_figure
from kitegully.twin.landcover import CLASSES
from kitegully.twin.texture import hillshade

CLASS_COLOURS = {
    "bare_eroded": "#d9b38c", "ploughed": "#8c6239", "grass": "#b5d56a", "shrub": "#4c7a2a", "tree": "#1f4d1a",
    "track": "#e6e1d3", "building": "#d62728", "water": "#3a7dc9", "gully": "#f2e14c",
}


def _read_decimated(path: Path, max_px: int):
    with rasterio.open(path) as src:
        f = max(1, int(np.ceil(max(src.width, src.height) / max_px)))
        out_shape = (max(1, src.height // f), max(1, src.width // f))
        resampling = rasterio.enums.Resampling.nearest if src.dtypes[0] == "uint8" else rasterio.enums.Resampling.average
        a = src.read(1, out_shape=out_shape, resampling=resampling)
        b = src.bounds
        cell = (b.right - b.left) / out_shape[1]
    return a, (b.left, b.right, b.bottom, b.top), cell


def _axes(ax, extent):
    map_axes(ax, extent)
    ax.tick_params(axis="x", labelrotation=30)


def hillshade_gullies(dtm: Path, centrelines: Path, out: Path, max_px: int = 1500, attribution: str | None = None) -> None:
    """Shaded DTM (sun from the east, as Fig. 8) with the truth gully network coloured by depth.

    Parameters
    ----------
    dtm : Path
        The truth DTM GeoTIFF.
    centrelines : Path
        The truth gully centrelines (``depth_m`` and ``width_m`` per reach).
    out : Path
        The PNG written.
    max_px : int
        Largest side of the raster drawn (px); the raster is decimated by a whole factor to fit.
    attribution : str or None
        Data attribution printed on the figure; None prints none.
    """
    z, extent, cell = _read_decimated(dtm, max_px)
    zp = np.pad(np.nan_to_num(z, nan=np.nanmean(z)), 1, mode="edge")
    hs = hillshade(zp, cell, 90.0, 35.0)[1:-1, 1:-1]
    fig, ax = new_figure(figsize=(7.5, 5.5))
    ax.imshow(hs, extent=extent, cmap="gray", vmin=0, vmax=1.6)
    im = ax.imshow(z, extent=extent, cmap="terrain", alpha=0.35)
    cb = fig.colorbar(im, ax=ax, shrink=0.7)
    cb.set_label("Elevation (m)")
    cl = gpd.read_file(centrelines)
    if len(cl):
        cl.plot(ax=ax, column="depth_m", cmap="autumn_r", linewidth=0.6 + 2.0 * cl["width_m"] / cl["width_m"].max(),
                legend=True, legend_kwds={"label": "Gully depth (m)", "shrink": 0.7})
    _axes(ax, extent)
    ax.set_title("Twin DTM (hillshade, sun from east)\nand true gully network")
    save_figure(fig, out, attribution)


def landcover_map(landcover: Path, out: Path, max_px: int = 1500, attribution: str | None = None) -> None:
    """Land-cover classes with a legend.

    Parameters
    ----------
    landcover : Path
        The land-cover GeoTIFF (class codes).
    out : Path
        The PNG written.
    max_px : int
        Largest side of the raster drawn (px); the raster is decimated by a whole factor to fit.
    attribution : str or None
        Data attribution printed on the figure; None prints none.
    """
    a, extent, _ = _read_decimated(landcover, max_px)
    codes = list(CLASSES)
    cmap = ListedColormap(["white"] + [CLASS_COLOURS[CLASSES[c]] for c in codes])
    norm = BoundaryNorm(np.arange(-0.5, max(codes) + 1.5), cmap.N)
    fig, ax = new_figure(figsize=(7.5, 5.5))
    ax.imshow(a, extent=extent, cmap=cmap, norm=norm, interpolation="nearest")
    shares = np.bincount(a.ravel(), minlength=max(codes) + 1) / a.size * 100
    ax.legend(handles=[Patch(color=CLASS_COLOURS[CLASSES[c]], label=f"{CLASSES[c]} ({shares[c]:.1f} %)") for c in codes],
              loc="upper left", bbox_to_anchor=(1.01, 1.0), title="Land cover")
    _axes(ax, extent)
    ax.set_title("Twin land cover")
    save_figure(fig, out, attribution)


def site_overview(texture: Path, targets: Path, checkpoints: Path, heads: Path, out: Path, max_px: int = 1500,
                  attribution: str | None = None) -> None:
    """True-colour texture with GCP targets, checkpoints and digitised gully heads.

    Parameters
    ----------
    texture : Path
        The texture GeoTIFF; bands 1 to 3 are drawn as RGB.
    targets, checkpoints : Path
        CSV tables of GCP targets and checkpoints (``x``, ``y``).
    heads : Path
        The digitised gully heads (points).
    out : Path
        The PNG written.
    max_px : int
        Largest side of the texture drawn (px); the texture is decimated by a whole factor to fit.
    attribution : str or None
        Data attribution printed on the figure; None prints none.
    """
    with rasterio.open(texture) as src:
        f = max(1, int(np.ceil(max(src.width, src.height) / max_px)))
        shape = (3, max(1, src.height // f), max(1, src.width // f))
        rgb = src.read([1, 2, 3], out_shape=shape, resampling=rasterio.enums.Resampling.average)
        b = src.bounds
    extent = (b.left, b.right, b.bottom, b.top)
    img = np.moveaxis(rgb, 0, -1).astype(float) / 255.0
    img = np.clip(img / max(np.percentile(img, 99), 1e-3), 0, 1)
    fig, ax = new_figure(figsize=(7.5, 5.5))
    ax.imshow(img, extent=extent)
    cp = pd.read_csv(checkpoints)
    gc = pd.read_csv(targets)
    ax.scatter(cp["x"], cp["y"], s=3, c="k", label=f"checkpoints (n = {len(cp)})")
    ax.scatter(gc["x"], gc["y"], s=60, marker="+", c="red", linewidths=1.5, label=f"GCP targets (n = {len(gc)})")
    hd = gpd.read_file(heads)
    if len(hd):
        ax.scatter(hd.geometry.x, hd.geometry.y, s=12, marker="^", facecolors="none", edgecolors="yellow",
                   label=f"digitised gully heads (n = {len(hd)})")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0))
    _axes(ax, extent)
    ax.set_title("Twin site overview (true-colour texture)")
    save_figure(fig, out, attribution)


def twin_figures(dtm: str | Path, centrelines: str | Path, landcover: str | Path, texture: str | Path,
                 targets: str | Path, checkpoints: str | Path, heads: str | Path, hillshade_png: str | Path,
                 landcover_png: str | Path, overview_png: str | Path, attribution: str | None = None) -> None:
    """The twin's three report figures: hillshade with gullies, land-cover map, site overview.

    Parameters
    ----------
    dtm, centrelines, landcover, texture, targets : path
        The twin's truth (epoch 1).
    checkpoints, heads : path
        The observed checkpoints and digitised gully heads.
    hillshade_png, landcover_png, overview_png : path
        The figures written.
    attribution : str, optional
        Data attribution printed on the figures.
    """
    hillshade_gullies(dtm, centrelines, hillshade_png, attribution=attribution)
    landcover_map(landcover, landcover_png, attribution=attribution)
    site_overview(texture, targets, checkpoints, heads, overview_png, attribution=attribution)
