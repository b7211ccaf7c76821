"""Figures like Höfle et al. (2013) Figs 8-12: TCI, polygons over hillshade, medial axes,
cross-sections along one gully, and the comparison with the manual outlines."""

from __future__ import annotations

import geopandas as gpd
import numpy as np
import pandas as pd
from matplotlib import colormaps
from matplotlib.lines import Line2D

from kitegully.io.figures import map_axes, new_figure, save_figure
from kitegully.io.raster import GridSpec
from kitegully.terrain.shading import hillshade


def _extent(grid: GridSpec):
    x0, y0, x1, y1 = grid.bounds
    return [x0, x1, y0, y1]


def _thin(a: np.ndarray, max_px: int) -> tuple[np.ndarray, int]:
    k = max(1, int(np.ceil(max(a.shape) / max_px)))
    return a[::k, ::k], k


def polygon_map(dem: np.ndarray, grid: GridSpec, tci: np.ndarray, tci_threshold: float, polys: dict[float, gpd.GeoDataFrame],
                thalweg: gpd.GeoDataFrame, transects: gpd.GeoDataFrame, axes: gpd.GeoDataFrame, sections: gpd.GeoDataFrame,
                morph: pd.DataFrame, path: str, max_px: int = 2000, attribution: str | None = None) -> None:
    """Three panels: (a) TCI with thalweg and dams (Fig. 8), (b) polygons at every fill-depth
    threshold over the hillshade with medial axes (Figs 9-10), (c) width, depth and
    cross-sectional area along the main medial axis of the polygon with the longest axes (Fig. 11).

    Parameters
    ----------
    dem : ndarray (H, W)
        DEM (m) for the hillshade.
    grid : GridSpec
        Grid of ``dem`` and ``tci``.
    tci : ndarray (H, W)
        Topographic convergence index.
    tci_threshold : float
        TCI threshold of the thalweg, for the legend.
    polys : mapping
        Polygon set (GeoDataFrame) of each fill-depth threshold (m).
    thalweg, transects : GeoDataFrame
        Thalweg lines and transects (dams).
    axes : GeoDataFrame
        Medial axes (``polygon_id``, optional ``branch``).
    sections : GeoDataFrame
        Cross-sections (``polygon_id, station_m, width_m, depth_m, area_m2, slab_m``, optional ``branch``).
    morph : DataFrame
        Per-polygon morphometry (``polygon_id, length_m``); the polygon with the longest axes is drawn in (c).
    path : str
        Output PNG file.
    max_px : int
        Rasters are thinned to at most this many cells along each side.
    attribution : str or None
        Line written below the figure.
    """
    fig, ax = new_figure(3, 1, figsize=(8.0, 15.0), gridspec_kw={"height_ratios": [1, 1, 0.6]})
    ext = _extent(grid)
    hs, _ = _thin(hillshade(dem, grid.cell), max_px)
    t, _ = _thin(tci, max_px)
    im = ax[0].imshow(t, extent=ext, cmap="viridis", vmin=np.nanpercentile(t, 2), vmax=np.nanpercentile(t, 99.5), interpolation="nearest")
    fig.colorbar(im, ax=ax[0], label="TCI = ln(a / tan β) (a in m²/m)", shrink=0.8)
    if len(thalweg):
        thalweg.plot(ax=ax[0], color="white", linewidth=0.8)
    if len(transects):
        transects.plot(ax=ax[0], color="red", linewidth=0.5)
    ax[0].legend(handles=[Line2D([], [], color="white", label=f"thalweg (TCI > {tci_threshold:g})"), Line2D([], [], color="red", label="dams (transects)")],
                 loc="lower left", facecolor="0.6")
    ax[0].set_title("(a) topographic convergence index, thalweg and dams")
    ax[1].imshow(hs, extent=ext, cmap="gray", vmin=0, vmax=1, interpolation="nearest")
    cmap = colormaps["plasma"]
    ts = sorted(polys)
    handles = []
    for i, thr in enumerate(ts):
        col = cmap(i / max(len(ts) - 1, 1))
        if len(polys[thr]):
            polys[thr].boundary.plot(ax=ax[1], color=col, linewidth=0.6)
        handles.append(Line2D([], [], color=col, label=f"FD ≥ {thr:g} m"))
    if len(axes):
        axes.plot(ax=ax[1], color="cyan", linewidth=0.6)
        handles.append(Line2D([], [], color="cyan", label="medial axis"))
    if len(sections):
        sections.plot(ax=ax[1], color="lime", linewidth=0.4)
        handles.append(Line2D([], [], color="lime", label="cross-sections"))
    pid = None
    if len(sections) and len(morph):
        pid = int(morph.sort_values("length_m", ascending=False)["polygon_id"].iloc[0])
        main_axis = axes[(axes["polygon_id"] == pid) & ((axes["branch"] == 0) if "branch" in axes else True)]
        if len(main_axis):
            # black with a white halo: outside the plasma ramp of the thresholds (whose last colour is yellow)
            xs, ys = main_axis.geometry.iloc[0].xy
            ax[1].plot(xs, ys, color="white", linewidth=3.0, solid_capstyle="round")
            ax[1].plot(xs, ys, color="black", linewidth=1.4, solid_capstyle="round")
            ax[1].plot(xs[0], ys[0], "o", color="black", mec="white", ms=5)
            handles.append(Line2D([], [], color="black", lw=1.4, marker="o", markevery=[0], mec="white",
                                  label=f"main axis of polygon {pid} (c; dot = 0 m)"))
    ax[1].legend(handles=handles, loc="lower left", fontsize=7)
    ax[1].set_title("(b) gully polygons by fill-depth threshold over the hillshade")
    for a in ax[:2]:
        map_axes(a, ext)
    a = ax[2]
    if pid is not None:
        s = sections[sections["polygon_id"] == pid]
        if "branch" in s:  # the main stem (branch 0); tributaries have their own stations
            s = s[s["branch"] == 0]
        s = s.sort_values("station_m")
        a.bar(s["station_m"], s["area_m2"], width=0.8 * s["slab_m"].iloc[0], color="0.7", label="cross-sectional area (m²)")
        a.set_xlabel(f"distance along the medial axis of polygon {pid} (m)")
        a.set_ylabel("area (m²)")
        b = a.twinx()
        b.plot(s["station_m"], s["width_m"], "o-", color="tab:blue", ms=3, label="width (m)")
        b.plot(s["station_m"], s["depth_m"], "s-", color="tab:red", ms=3, label="max depth (m)")
        b.set_ylabel("width, depth (m)")
        h1, l1 = a.get_legend_handles_labels()
        h2, l2 = b.get_legend_handles_labels()
        a.legend(h1 + h2, l1 + l2, loc="upper right", fontsize=7)
    a.set_title("(c) cross-sections every ~10 m along the main medial axis (black in b)")
    save_figure(fig, path, attribution)


def comparison_map(dem: np.ndarray, grid: GridSpec, auto: gpd.GeoDataFrame, manual: gpd.GeoDataFrame, truth: gpd.GeoDataFrame,
                   path: str, max_px: int = 2000, attribution: str | None = None) -> None:
    """Fig. 12 analogue: the t = 0.5 m polygons, the manual union and intersection, the true outlines.

    Parameters
    ----------
    dem : ndarray (H, W)
        DEM (m) for the hillshade.
    grid : GridSpec
        Grid of ``dem``.
    auto : GeoDataFrame
        Automatic polygons.
    manual : GeoDataFrame
        One outline per simulated operator.
    truth : GeoDataFrame
        True gully polygons.
    path : str
        Output PNG file.
    max_px : int
        The hillshade is thinned to at most this many cells along each side.
    attribution : str or None
        Line written below the figure.
    """
    import shapely

    fig, ax = new_figure(figsize=(9.0, 6.5))
    ext = _extent(grid)
    hs, _ = _thin(hillshade(dem, grid.cell), max_px)
    ax.imshow(hs, extent=ext, cmap="gray", vmin=0, vmax=1, interpolation="nearest")
    geoms = [g for g in manual.geometry if not g.is_empty]
    union = shapely.union_all(geoms) if geoms else shapely.Polygon()
    inter = geoms[0] if geoms else shapely.Polygon()
    for g in geoms[1:]:
        inter = inter.intersection(g)
    gpd.GeoSeries([union], crs=manual.crs).plot(ax=ax, color="tab:orange", alpha=0.35)
    gpd.GeoSeries([inter], crs=manual.crs).plot(ax=ax, color="tab:orange", alpha=0.8)
    truth.boundary.plot(ax=ax, color="lime", linewidth=0.6)
    if len(auto):
        auto.boundary.plot(ax=ax, color="magenta", linewidth=0.8)
    ax.legend(handles=[Line2D([], [], color="tab:orange", alpha=0.35, lw=6, label="manual union (9 operators)"),
                       Line2D([], [], color="tab:orange", lw=6, label="manual intersection"),
                       Line2D([], [], color="lime", label="true gully outline"),
                       Line2D([], [], color="magenta", label="automatic, FD ≥ 0.5 m")], loc="lower left", fontsize=7)
    map_axes(ax, ext)
    ax.set_title("Automatic polygons vs simulated manual outlines and the truth")
    save_figure(fig, path, attribution)
