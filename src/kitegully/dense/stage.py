"""The dense stage end to end: georeferenced model → DSM, correlation, orthophoto, shading.

Products (all in the site CRS): ``dsm.tif`` (float32, NaN nodata), ``correlation.tif``
(NCC at the chosen elevation), ``orthophoto.tif`` (uint8 bands, 0 = nodata),
``hillshade.png``, ``openness.png`` and ``dense_summary.csv`` (coverage, speed, memory).
"""

from __future__ import annotations

import logging
import resource
import time
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import pandas as pd

from kitegully import InputError
from kitegully.dense.matching import MatchParams
from kitegully.dense.ortho import orthophoto
from kitegully.dense.shading import hillshade, openness
from kitegully.dense.surface import dense_surface
from kitegully.dense.views import ViewSet, read_offset, views_from_reconstruction
from kitegully.io.figures import new_figure, save_figure
from kitegully.io.raster import GridSpec, write_raster
from kitegully.io.tables import write_table

log = logging.getLogger(__name__)


def peak_memory_mb() -> float:
    """Peak resident memory of this process (MB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def read_site_extent(site_json: str | Path) -> dict[str, float]:
    """``extent`` (xmin, ymin, xmax, ymax) of a twin's ``site.json`` (what a planner knows)."""
    import json

    path = Path(site_json)
    try:
        ext = json.loads(path.read_text(encoding="utf-8"))["extent"]
        return {k: float(ext[k]) for k in ("xmin", "ymin", "xmax", "ymax")}
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise InputError(f"{path}: cannot read extent xmin, ymin, xmax, ymax ({exc})") from None


def site_grid(views: ViewSet, cfg: Mapping[str, Any], crs: str, site_json: str | Path | None = None) -> GridSpec:
    """DSM grid: the configured extent, the site's extent (``extent: site``, from
    ``site_json``) or the trimmed tie-point extent (``extent: null``); origin snapped to
    whole multiples of the cell (so it aligns with any grid of the same cell)."""
    cell = float(cfg["cell_m"])
    ext = cfg["extent"]
    if ext == "site":
        if site_json is None:
            raise InputError("dense.extent is 'site' but the site has no site.json (use null or an explicit extent)")
        ext = read_site_extent(site_json)
    if ext is None:
        P = views.sparse_points
        if len(P) < 10:
            raise InputError("dense.extent is null but the model has fewer than 10 tie points to derive it from")
        q = float(cfg["extent_percentile"])
        xmin, xmax = np.percentile(P[:, 0], [q, 100 - q]) + views.offset[0]
        ymin, ymax = np.percentile(P[:, 1], [q, 100 - q]) + views.offset[1]
    else:
        xmin, ymin, xmax, ymax = (float(ext[k]) for k in ("xmin", "ymin", "xmax", "ymax"))
        if xmax <= xmin or ymax <= ymin:
            raise InputError(f"dense.extent: xmax/ymax must exceed xmin/ymin, got {dict(ext)}")
    x0 = np.floor(xmin / cell) * cell
    y0 = np.ceil(ymax / cell) * cell
    w = int(np.ceil((xmax - x0) / cell))
    h = int(np.ceil((y0 - ymin) / cell))
    return GridSpec(float(x0), float(y0), cell, w, h, crs)


NODATA_COLOUR = "#e8b4b4"


def _show(ax, img, grid: GridSpec, max_px: int, cmap: str = "gray", **kw):
    """Decimated raster in map coordinates; nodata cells in a pale red with a legend entry."""
    import matplotlib
    from matplotlib.patches import Patch

    step = max(1, int(np.ceil(max(img.shape[-2:]) / max_px)))
    xmin, ymin, xmax, ymax = grid.bounds
    cm = matplotlib.colormaps[cmap].copy()
    cm.set_bad(NODATA_COLOUR)
    im = ax.imshow(img[..., ::step, ::step], extent=(xmin, xmax, ymin, ymax), interpolation="nearest", cmap=cm, **kw)
    if np.isnan(img).any():
        ax.legend(handles=[Patch(color=NODATA_COLOUR, label="no elevation (masked)")], loc="lower left", fontsize=7)
    return im


def shading_figures(dsm: np.ndarray, grid: GridSpec, cfg: Mapping[str, Any], hill_png: str | Path,
                    open_png: str | Path) -> None:
    """Hillshade and openness figures of the DSM (Fig. 8 style), axes in site metres."""
    sh = cfg["shading"]
    hs = hillshade(dsm, grid.cell, sh["azimuth_deg"], sh["altitude_deg"])
    fig, ax = new_figure(figsize=(7, 6))
    im = _show(ax, np.where(np.isfinite(dsm), hs, np.nan), grid, cfg["figure_max_px"], vmin=0, vmax=1)
    ax.set(xlabel="Easting (m)", ylabel="Northing (m)",
           title=f"DSM hillshade (sun az {sh['azimuth_deg']:g}°, alt {sh['altitude_deg']:g}°), cell {grid.cell:g} m")
    ax.ticklabel_format(useOffset=False, style="plain")
    fig.colorbar(im, ax=ax, shrink=0.7, label="illumination (0–1)")
    save_figure(fig, hill_png)
    op = openness(dsm, grid.cell, sh["openness_radius_m"])
    fig, ax = new_figure(figsize=(7, 6))
    lo, hi = np.nanpercentile(op, [2, 98]) if np.isfinite(op).any() else (60, 90)
    im = _show(ax, op, grid, cfg["figure_max_px"], vmin=lo, vmax=hi)
    ax.set(xlabel="Easting (m)", ylabel="Northing (m)",
           title=f"Positive openness within {sh['openness_radius_m']:g} m (sky-view-like shading)")
    ax.ticklabel_format(useOffset=False, style="plain")
    fig.colorbar(im, ax=ax, shrink=0.7, label="openness (°); low = hollows, gullies")
    save_figure(fig, open_png)


def run_dense_stage(model_dir: str | Path, transform_json: str | Path | None, image_dir: str | Path, crs: str,
                    cfg: Mapping[str, Any], threads: int, out: Mapping[str, str | Path],
                    site_json: str | Path | None = None) -> dict:
    """Run matching, orthophoto and shading; write the products named in ``out``
    (keys ``dsm, correlation, orthophoto, hillshade, openness, summary``). Returns the summary."""
    import numba
    import pycolmap

    numba.set_num_threads(max(1, min(int(threads), numba.config.NUMBA_NUM_THREADS)))
    model_dir = Path(model_dir)
    if not (model_dir / "images.bin").exists() and not (model_dir / "images.txt").exists():
        raise InputError(f"{model_dir}: not a COLMAP model folder (no images.bin or images.txt)")
    rec = pycolmap.Reconstruction(str(model_dir))
    views = views_from_reconstruction(rec, image_dir, read_offset(transform_json), where=str(model_dir))
    grid = site_grid(views, cfg, crs, site_json)
    params = MatchParams.from_config(cfg["matching"])
    log.info("dense: %d images, grid %d x %d cells of %.3f m (%.2f ha), %d levels",
             len(views.images), grid.width, grid.height, grid.cell, grid.width * grid.height * grid.cell ** 2 / 1e4,
             params.levels)
    t0 = time.perf_counter()
    res = dense_surface(views, grid, params, cfg["tile_cells"], cfg["overlap_cells"], cfg["max_cached_images"])
    t_match = time.perf_counter() - t0
    if not np.isfinite(res.dsm).any():
        raise InputError(f"{model_dir}: dense matching found no valid cell (check the images and the model's orientation)")
    write_raster(out["dsm"], res.dsm, grid, tags={"units": "m", "nodata": "NaN"})
    write_raster(out["correlation"], res.ncc, grid, tags={"units": "NCC (-1..1)"})
    oc = cfg["orthophoto"]
    t1 = time.perf_counter()
    img, og, _ = orthophoto(views, res.dsm, grid, oc["upsample"], oc["tile_cells"], oc["overlap_m"],
                            oc["occlusion_tolerance_m"], cfg["max_cached_images"])
    t_ortho = time.perf_counter() - t1
    names = ["R", "G", "B", "NIR"][: img.shape[0]] if img.shape[0] >= 3 else ["grey"] * img.shape[0]
    write_raster(out["orthophoto"], img, og, nodata=0, band_names=names)
    shading_figures(res.dsm, grid, cfg, out["hillshade"], out["openness"])
    cells = grid.width * grid.height
    summary = {
        "images": len(views.images), "cell_m": grid.cell, "width_cells": grid.width, "height_cells": grid.height,
        "area_km2": cells * grid.cell ** 2 / 1e6, "tiles": res.tiles,
        "seen_by_2_or_more_pct": 100.0 * float((res.nseen >= 2).mean()),
        "valid_pct": 100.0 * float(np.isfinite(res.dsm).mean()),
        "coverage_of_seen_pct": 100.0 * res.coverage(),
        "median_ncc": float(np.nanmedian(res.ncc)),
        "matching_s": t_match, "orthophoto_s": t_ortho, "cells_per_s": cells / t_match,
        "peak_memory_mb": peak_memory_mb(), "threads": int(threads),
    }
    area_ext = 3.18e6 / 0.2 ** 2
    summary["extrapolated_3_18_km2_at_0_2_m_h"] = area_ext / summary["cells_per_s"] / 3600.0
    write_table(pd.DataFrame({"quantity": list(summary), "value": [summary[k] for k in summary]}), out["summary"])
    log.info("dense: %.1f%% of the cells seen by >= 2 images are valid; %.0f cells/s; peak %.0f MB",
             summary["coverage_of_seen_pct"], summary["cells_per_s"], summary["peak_memory_mb"])
    return summary
