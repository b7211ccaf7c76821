"""The dense stage: its parameters and its entry point :func:`match_dense_surface`.

:func:`match_dense_surface` turns the georeferenced model into a DSM, correlation raster,
true orthophoto and relief shading; :class:`DenseParams` holds the ``dense`` config section.

Products (all in the site CRS): ``dsm.tif`` (float32, NaN nodata), ``correlation.tif``
(NCC at the chosen elevation), ``orthophoto.tif`` (uint8 bands, an internal mask band marks cells no image sees; their values stay 0),
``hillshade.png``, ``openness.png`` and ``dense_summary.csv`` (coverage, speed, memory).
"""

from __future__ import annotations

import logging
import resource
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import pandas as pd

from kitegully import InputError
from kitegully.config import checked_number, config_section
from kitegully.dense.cell import choose_cell
from kitegully.dense.datum import DatumParams, check_datum
from kitegully.dense.matching import MatchParams
from kitegully.dense.ortho import orthophoto
from kitegully.dense.shading import openness
from kitegully.dense.surface import dense_surface
from kitegully.dense.views import ViewSet, read_offset, views_from_reconstruction
from kitegully.io.figures import map_axes, new_figure, save_figure
from kitegully.io.raster import GridSpec, write_raster
from kitegully.io.tables import write_table
from kitegully.terrain.shading import hillshade

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class OrthoParams:
    """True orthophoto (``dense.orthophoto``).

    Attributes
    ----------
    upsample : int
        Orthophoto cells per DSM cell side (ortho cell = ``cell_m / upsample``; [I] the
        images' GSD is finer than the DSM cell).
    tile_cells : int
        Orthophoto tile side (ortho cells).
    overlap_m : float
        DSM margin around a tile for the occlusion test (m; [I] longer than the shadow of
        the tallest object at the images' viewing angles).
    occlusion_tolerance_m : float
        A line of sight is blocked where the DSM rises this much above it (m; [I] about
        the DSM's noise).
    """

    upsample: int
    tile_cells: int
    overlap_m: float
    occlusion_tolerance_m: float

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any]) -> "OrthoParams":
        """Build from ``dense.orthophoto``; raises InputError naming a bad key."""
        config_section(cfg, "dense.orthophoto", cls.__dataclass_fields__)
        checked_number(cfg, "upsample", "dense.orthophoto", 1, strict=False)
        checked_number(cfg, "tile_cells", "dense.orthophoto", 16, strict=False)
        checked_number(cfg, "overlap_m", "dense.orthophoto", strict=False)
        checked_number(cfg, "occlusion_tolerance_m", "dense.orthophoto", strict=False)
        return cls(**{k: cfg[k] for k in cls.__dataclass_fields__})


@dataclass(frozen=True)
class ShadingParams:
    """Relief shading figures (``dense.shading``).

    Attributes
    ----------
    azimuth_deg, altitude_deg : float
        Hillshade sun azimuth from north and elevation (deg).
    openness_radius_m : float
        Search radius of the positive-openness shading (m; [I] a few gully widths).
    """

    azimuth_deg: float
    altitude_deg: float
    openness_radius_m: float

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any]) -> "ShadingParams":
        """Build from ``dense.shading``; raises InputError naming a bad key."""
        config_section(cfg, "dense.shading", cls.__dataclass_fields__)
        if not (0 <= cfg["azimuth_deg"] <= 360 and 0 < cfg["altitude_deg"] <= 90):
            raise InputError("dense.shading: azimuth_deg must lie in 0-360 and altitude_deg in (0, 90]")
        checked_number(cfg, "openness_radius_m", "dense.shading")
        return cls(**{k: cfg[k] for k in cls.__dataclass_fields__})


@dataclass(frozen=True)
class DenseParams:
    """Parameters of the dense stage (the ``dense`` config section).

    Attributes
    ----------
    cell_m : float or "auto"
        DSM cell size (m; [P] 0.20 m in Feurer et al. 2018), or ``auto`` = 2 × the GSD
        measured on the oriented model, rounded to one significant digit ([I] see
        :mod:`kitegully.dense.cell`; the matching window, in cells, scales with it).
    extent : None, "site" or dict
        DSM extent: None = the tie points' extent trimmed by ``extent_percentile``;
        ``site`` = the twin's ``site.json`` extent; else ``{xmin, ymin, xmax, ymax}`` in
        the site CRS (m).
    extent_percentile : float
        Percent of tie points trimmed on each side for the automatic extent (0-10).
    tile_cells : int
        Core tile side (DSM cells); memory grows with its square.
    overlap_cells : int
        Overlap added on every side of a tile (cells; [I] a multiple of 2^(levels-1) so
        the pyramid levels stay aligned).
    max_cached_images : int
        Image pyramids kept in memory (LRU cache).
    matching : MatchParams
        Object-space matching (``dense.matching``; see :class:`kitegully.dense.matching.MatchParams`).
    orthophoto : OrthoParams
        True orthophoto (``dense.orthophoto``).
    shading : ShadingParams
        Relief shading (``dense.shading``).
    figure_max_px : int
        Figures show the rasters decimated to at most this many pixels per side.
    threads : int
        Threads of the rule (Snakemake ``threads:``; the script passes the granted count).
    datum : DatumParams
        Vertical datum check of the DSM at the GCP targets (``dense.datum``, optional;
        absent = disabled; see :mod:`kitegully.dense.datum`).
    """

    cell_m: float | str
    extent: Any
    extent_percentile: float
    tile_cells: int
    overlap_cells: int
    max_cached_images: int
    matching: MatchParams
    orthophoto: OrthoParams
    shading: ShadingParams
    figure_max_px: int
    threads: int
    datum: DatumParams = DatumParams.from_config(None)

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any]) -> "DenseParams":
        """Build from the ``dense`` config section; raises InputError naming a bad key."""
        config_section(cfg, "dense", [k for k in cls.__dataclass_fields__ if k != "datum"], optional=("datum",))
        if cfg["cell_m"] != "auto":
            if isinstance(cfg["cell_m"], (str, bool)) or cfg["cell_m"] is None:
                raise InputError(f"dense.cell_m: must be a number of metres or 'auto', got {cfg['cell_m']!r}")
            checked_number(cfg, "cell_m", "dense")
        ext = cfg["extent"]
        if ext is not None and ext != "site":
            config_section(ext, "dense.extent", ("xmin", "ymin", "xmax", "ymax"))
            if ext["xmax"] <= ext["xmin"] or ext["ymax"] <= ext["ymin"]:
                raise InputError(f"dense.extent: xmax/ymax must exceed xmin/ymin, got {dict(ext)}")
            ext = {k: ext[k] for k in ("xmin", "ymin", "xmax", "ymax")}
        if not 0 <= cfg["extent_percentile"] <= 10:
            raise InputError(f"dense.extent_percentile: must lie in 0-10, got {cfg['extent_percentile']!r}")
        for key, low in (("tile_cells", 16), ("overlap_cells", 0), ("max_cached_images", 2), ("figure_max_px", 100),
                         ("threads", 1)):
            checked_number(cfg, key, "dense", low, strict=False)
        config_section(cfg["matching"], "dense.matching", MatchParams.REQUIRED, optional=MatchParams.OPTIONAL)
        return cls(
            cell_m=cfg["cell_m"], extent=ext, extent_percentile=cfg["extent_percentile"], tile_cells=cfg["tile_cells"],
            overlap_cells=cfg["overlap_cells"], max_cached_images=cfg["max_cached_images"],
            matching=MatchParams.from_config(cfg["matching"]), orthophoto=OrthoParams.from_config(cfg["orthophoto"]),
            shading=ShadingParams.from_config(cfg["shading"]), figure_max_px=cfg["figure_max_px"], threads=cfg["threads"],
            datum=DatumParams.from_config(cfg.get("datum")),
        )


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


def site_grid(views: ViewSet, params: DenseParams, crs: str, site_json: str | Path | None = None) -> GridSpec:
    """DSM grid of ``params.cell_m`` metres (``auto`` is resolved before, by
    :func:`kitegully.dense.cell.choose_cell`): the configured extent, the site's extent (``extent: site``, from
    ``site_json``) or the trimmed tie-point extent (``extent: null``); origin snapped to
    whole multiples of the cell (so it aligns with any grid of the same cell).

    Parameters
    ----------
    views : ViewSet
        The model's views; their tie points give the extent when ``extent`` is null.
    params : DenseParams
        ``cell_m`` (m, a number by now), ``extent`` and ``extent_percentile``.
    crs : str
        Site CRS of the grid.
    site_json : path or None
        The twin's ``site.json``; needed by ``extent: site``.

    Returns
    -------
    GridSpec
        The smallest grid of that cell covering the extent (site CRS).

    Raises
    ------
    InputError
        ``extent: site`` without ``site_json``, ``extent: null`` with fewer than 10 tie points, or an empty extent.
    """
    cell = float(params.cell_m)
    ext = params.extent
    if ext == "site":
        if site_json is None:
            raise InputError("dense.extent is 'site' but the site has no site.json (use null or an explicit extent)")
        ext = read_site_extent(site_json)
    if ext is None:
        P = views.sparse_points
        if len(P) < 10:
            raise InputError("dense.extent is null but the model has fewer than 10 tie points to derive it from")
        q = float(params.extent_percentile)
        xmin, xmax = np.percentile(P[:, 0], [q, 100 - q]) + views.offset[0]
        ymin, ymax = np.percentile(P[:, 1], [q, 100 - q]) + views.offset[1]
    else:
        xmin, ymin, xmax, ymax = (float(ext[k]) for k in ("xmin", "ymin", "xmax", "ymax"))
        if xmax <= xmin or ymax <= ymin:
            raise InputError(f"dense.extent: xmax/ymax must exceed xmin/ymin, got {dict(ext)}")
    return GridSpec.covering((xmin, ymin, xmax, ymax), cell, crs)


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


def shading_figures(dsm: np.ndarray, grid: GridSpec, sh: ShadingParams, figure_max_px: int, hill_png: str | Path,
                    open_png: str | Path) -> None:
    """Hillshade and openness figures of the DSM (Fig. 8 style), axes in site metres.

    Parameters
    ----------
    dsm : ndarray (H, W)
        The DSM (m, NaN = no value) on ``grid``.
    grid : GridSpec
        Its grid (site CRS).
    sh : ShadingParams
        Sun azimuth and altitude (degrees) and openness radius (m).
    figure_max_px : int
        The rasters are decimated to at most this many pixels per side.
    hill_png, open_png : path
        Output files of the hillshade and the openness figure.
    """
    hs = hillshade(dsm, grid.cell, sh.azimuth_deg, sh.altitude_deg)
    fig, ax = new_figure(figsize=(7, 6))
    im = _show(ax, np.where(np.isfinite(dsm), hs, np.nan), grid, figure_max_px, vmin=0, vmax=1)
    map_axes(ax)
    ax.set_title(f"DSM hillshade (sun az {sh.azimuth_deg:g}°, alt {sh.altitude_deg:g}°), cell {grid.cell:g} m")
    fig.colorbar(im, ax=ax, shrink=0.7, label="illumination (0–1)")
    save_figure(fig, hill_png)
    op = openness(dsm, grid.cell, sh.openness_radius_m)
    fig, ax = new_figure(figsize=(7, 6))
    lo, hi = np.nanpercentile(op, [2, 98]) if np.isfinite(op).any() else (60, 90)
    im = _show(ax, op, grid, figure_max_px, vmin=lo, vmax=hi)
    map_axes(ax)
    ax.set_title(f"Positive openness within {sh.openness_radius_m:g} m (sky-view-like shading)")
    fig.colorbar(im, ax=ax, shrink=0.7, label="openness (°); low = hollows, gullies")
    save_figure(fig, open_png)


def match_dense_surface(model_dir: str | Path, transform_json: str | Path | None, image_dir: str | Path, crs: str,
                        params: DenseParams, threads: int, out: Mapping[str, str | Path],
                        site_json: str | Path | None = None, gcps: pd.DataFrame | None = None) -> dict:
    """Dense matching, orthophoto and shading of the georeferenced model; writes the products.

    Parameters
    ----------
    model_dir : path
        Georeferenced COLMAP model folder (local frame).
    transform_json : path or None
        The georef stage's ``transform.json`` (offset of the local frame); None = no offset.
    image_dir : path
        Folder of the prepared images the model names.
    crs : str
        Site CRS.
    params : DenseParams
        The stage's parameters.
    threads : int
        Threads granted to the rule (numba).
    out : mapping
        Product name → path; keys dsm, correlation, orthophoto, hillshade, openness, summary.
    site_json : path, optional
        The twin's ``site.json`` (needed by ``extent: site``).
    gcps : DataFrame, optional
        ``gcp_id, x, y, z`` of the targets the GCP adjustment used, for the datum check
        (``params.datum``); with ``out["datum"]`` the per-target table is written there.

    Returns
    -------
    dict
        The summary written to ``out["summary"]`` (coverage, speed, memory).

    Raises
    ------
    InputError
        Not a COLMAP model folder, no extent to derive, or no valid cell matched.

    Notes
    -----
    Cost O(cells x labels x views) for the matching (:func:`kitegully.dense.surface.dense_surface`).
    """
    import numba
    import pycolmap

    numba.set_num_threads(max(1, min(int(threads), numba.config.NUMBA_NUM_THREADS)))
    model_dir = Path(model_dir)
    if not (model_dir / "images.bin").exists() and not (model_dir / "images.txt").exists():
        raise InputError(f"{model_dir}: not a COLMAP model folder (no images.bin or images.txt)")
    rec = pycolmap.Reconstruction(str(model_dir))
    views = views_from_reconstruction(rec, image_dir, read_offset(transform_json), where=str(model_dir))
    mp = params.matching
    cell = choose_cell(params.cell_m, views, mp.window_half_cells)
    params = replace(params, cell_m=cell.cell_m)
    grid = site_grid(views, params, crs, site_json)
    log.info("dense: %d images, grid %d x %d cells of %.3f m (%.2f ha), %d levels",
             len(views.images), grid.width, grid.height, grid.cell, grid.width * grid.height * grid.cell ** 2 / 1e4,
             mp.levels)
    t0 = time.perf_counter()
    res = dense_surface(views, grid, mp, params.tile_cells, params.overlap_cells, params.max_cached_images)
    t_match = time.perf_counter() - t0
    if not np.isfinite(res.dsm).any():
        raise InputError(f"{model_dir}: dense matching found no valid cell (check the images and the model's orientation)")
    datum = None
    if params.datum.enabled:
        if gcps is None:
            raise InputError("dense.datum.enabled: the datum check needs the GCP file (the rule's gcp input)")
        datum = check_datum(res.dsm, grid, gcps, params.datum)
        log.info("dense: %s", datum.reason)
        if datum.applied:
            res.dsm -= np.float32(datum.offset_m)  # before the orthophoto, so it is rendered on the shifted surface
        if "datum" in out:
            write_table(datum.table, out["datum"])
    write_raster(out["dsm"], res.dsm, grid, tags={"units": "m", "nodata": "NaN"})
    write_raster(out["correlation"], res.ncc, grid, tags={"units": "NCC (-1..1)"})
    oc = params.orthophoto
    t1 = time.perf_counter()
    img, og, source = orthophoto(views, res.dsm, grid, oc.upsample, oc.tile_cells, oc.overlap_m,
                                 oc.occlusion_tolerance_m, params.max_cached_images)
    t_ortho = time.perf_counter() - t1
    names = ["R", "G", "B", "NIR"][: img.shape[0]] if img.shape[0] >= 3 else ["grey"] * img.shape[0]
    # cells no image sees are masked (internal mask band), not declared by a 0 nodata value
    write_raster(out["orthophoto"], img, og, band_names=names, mask=source >= 0, overview_resampling="average")
    shading_figures(res.dsm, grid, params.shading, params.figure_max_px, out["hillshade"], out["openness"])
    cells = grid.width * grid.height
    summary = {
        "images": len(views.images), "cell_m": grid.cell, "gsd_measured_m": cell.gsd_m, "width_cells": grid.width, "height_cells": grid.height,
        "area_km2": cells * grid.cell ** 2 / 1e6, "tiles": res.tiles,
        "seen_by_2_or_more_pct": 100.0 * float((res.nseen >= 2).mean()),
        "valid_pct": 100.0 * float(np.isfinite(res.dsm).mean()),
        "coverage_of_seen_pct": 100.0 * res.coverage(),
        "median_ncc": float(np.nanmedian(res.ncc)),
        "matching_s": t_match, "orthophoto_s": t_ortho, "cells_per_s": cells / t_match,
        "peak_memory_mb": peak_memory_mb(), "threads": int(threads),
    }
    if datum is not None:
        summary.update(datum.summary())
    area_ext = 3.18e6 / 0.2 ** 2
    summary["extrapolated_3_18_km2_at_0_2_m_h"] = area_ext / summary["cells_per_s"] / 3600.0
    write_table(pd.DataFrame({"quantity": list(summary), "value": [summary[k] for k in summary]}), out["summary"])
    log.info("dense: %.1f%% of the cells seen by >= 2 images are valid; %.0f cells/s; peak %.0f MB",
             summary["coverage_of_seen_pct"], summary["cells_per_s"], summary["peak_memory_mb"])
    return summary
