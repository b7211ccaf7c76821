"""The change stage as Snakemake tile jobs on tiled sites (issue 21).

:func:`kitegully.change.stage.detect_change` works on the whole common grid. A site with a
``tiling:`` section runs the same steps as five rules; the tiles are
:meth:`kitegully.terrain.tiling.TilingParams.tiles` of the common grid (names from the
config alone):

1. ``change_plan`` (once): the whole-grid numbers a tile cannot see: the highest epoch-1
   elevation (the nodata fill of the above-ground-object filter) and each epoch's σ with
   its source (checkpoints are sampled on the whole DEM).
2. ``change_stable_tile`` (per tile, read with halo A = void margin + object filter + 1
   cell): masks, matching voids, above-ground objects → stable ground, the co-registration's
   candidate cells, and dh before co-registration on stable ground.
3. ``change_coregister`` (once): the co-registration is one global fit. The stable and
   candidate cells of all tiles give the whole grid's masks (1 byte/cell); the same
   deterministic sub-sample of at most ``coreg_max_samples`` cells as untiled is fitted
   (Nuth & Kääb shift + plane, :func:`kitegully.change.coregister.fit_shift_plane`), DEM₂
   resampled at the sampled cells only. Stats before co-registration from the tiles' dh.
   With ``heteroscedastic``, the error model (:mod:`kitegully.change.error_model`) is fitted
   here once, as untiled, on the unchanged cells of the sampling lattice that the stable-tile
   jobs gathered with their predictors (DoD at those cells from the fitted co-registration),
   referred to the checkpoints' bins, and written to the co-registration JSON.
4. ``change_tile`` (per tile, halo B = void margin + half the coherence window + 1, at least
   the error model's predictor footprint when it is on): the co-registered DEM₂, DoD with
   voids, σ_DoD (× the model's factor), the four thresholds (GCD's 5 × 5 spatial
   coherence sees its neighbours across the seam through the halo) and, per budget row
   (mask, value) and method, the partial sums n, Σ erosion, Σ deposition, Σ σ².
5. ``change_merge`` (once): the rasters written from the tiles' cores; the budgets from the
   sums over tiles (:func:`kitegully.change.budget.budget_row_from_sums`); the variogram,
   the co-registration offset SD, headcuts, widening, tables and figures exactly as
   untiled, on the merged arrays (they need the whole site: the stable cells' median and
   NMAD, random pairs over the site, features anywhere).

Equality with the untiled stage: every per-cell value (DoD, σ, thresholded rasters, stable
ground) is computed from the same inputs by the same operations (windows of the same
coordinate vectors, bilinear samples per point), so the rasters are equal bit for bit, as
are the co-registration, variogram and the tables computed in the merge. Budget sums are
added tile by tile, so erosion, deposition, net and their SDs equal the untiled ones up to
the order of floating-point additions (relative 1e-12; tests/change/test_tiles.py). The
masks are rasterised on each tile's grid: a polygon edge passing within ~1e-9 m of a cell
centre could flip that cell (never seen).

Memory: tile jobs read both epoch DEMs whole (4 B/cell each, as the untiled stage) and
compute on their window; the merge holds the merged float rasters (z1, z2, DoD, σ: 16
B/cell) plus the variogram's work arrays, but never the per-row mask stack (bytes/cell ×
budget rows) or the threshold and co-registration work arrays of the untiled job.
"""

from __future__ import annotations

import json
import logging
import time
from math import ceil
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping, Sequence

import numpy as np
from scipy import ndimage

from kitegully import InputError
from kitegully.change import budget as bg
from kitegully.change import error_model as em
from kitegully.change import uncertainty as unc
from kitegully.change.coregister import (Coregistration, _sample, above_ground, above_ground_halo, fit_shift_plane,
                                         residual_stats)
from kitegully.change.dod import Epoch, dem_of_difference, load_epoch, matching_voids, on_common_grid, overlap_grid
from kitegully.change.params import THRESHOLD_METHODS, ChangeParams
from kitegully.change.stage import uncertainty_model, write_products
from kitegully.io.raster import GridSpec, Raster
from kitegully.terrain.tiling import TilingParams

if TYPE_CHECKING:
    import pandas as pd

log = logging.getLogger(__name__)

METHODS = ("raw", *THRESHOLD_METHODS)


# ----------------------------------------------------------------------------- windows


def _load(epochs: Sequence[Mapping[str, Any]], site_crs: str | None) -> tuple[Epoch, Epoch, GridSpec]:
    if len(epochs) != 2:
        raise InputError(f"change.epochs: exactly two epochs are needed, got {len(epochs)}")
    e1, e2 = (load_epoch(s, f"change.epochs[{i}]", site_crs) for i, s in enumerate(epochs))
    return e1, e2, overlap_grid(e1.dem.grid, e2.dem.grid, e1.path, e2.path)


def _void_halo(params: ChangeParams, cell: float) -> int:
    return int(ceil(params.void_margin_m / cell)) + 1 if params.min_correlation is not None else 0


def halos(params: ChangeParams, cell: float) -> tuple[int, int]:
    """Cells read beyond a tile: (stable-ground pass, DoD/threshold pass)."""
    obj = above_ground_halo(cell, params.stable_object_window_m) if params.stable_max_object_height_m is not None else 0
    void = _void_halo(params, cell)
    a, b = void + obj + 1, void + params.coherence_window // 2 + 1
    if params.heteroscedastic:  # both passes read the error model's predictors of their core cells
        ph = em.predictor_halo(cell, params.headcut_window_m, params.stable_object_window_m)
        a, b = max(a, ph), max(b, ph)
    return a, b


def _window(grid: GridSpec, tiling: TilingParams, name: str, halo: int) -> tuple[Any, slice, slice, slice, slice]:
    """The tile, its read window's row/col slices on ``grid`` and the core's slices inside the window."""
    t = tiling.tile((grid.height, grid.width), name)
    r0, c0 = max(0, t.r0 - halo), max(0, t.c0 - halo)
    r1, c1 = min(grid.height, t.r0 + t.h + halo), min(grid.width, t.c0 + t.w + halo)
    return t, slice(r0, r1), slice(c0, c1), slice(t.r0 - r0, t.r0 - r0 + t.h), slice(t.c0 - c0, t.c0 - c0 + t.w)


def resample_window(r: Raster, grid: GridSpec, rs: slice, cs: slice, dx: float = 0.0, dy: float = 0.0) -> np.ndarray:
    """:func:`kitegully.change.dod.resample` of the window ``rs, cs`` of ``grid`` (the same values, cell for cell).

    Parameters
    ----------
    r : Raster
        Source raster; NaN is nodata.
    grid : GridSpec
        The whole grid.
    rs, cs : slice
        Rows and columns of the window on ``grid``.
    dx, dy : float
        Shift east and north (m).

    Returns
    -------
    ndarray float32
        Samples on the window; NaN outside ``r``.
    """
    if grid == r.grid and dx == 0.0 and dy == 0.0:
        return r.data[rs, cs].astype(np.float32, copy=True)
    xs, ys = grid.cell_centres()
    rows, _ = r.grid.rowcol(np.zeros(1), ys + dy)
    _, cols = r.grid.rowcol(xs + dx, np.zeros(1))
    rr, cc = np.meshgrid(rows[rs], cols[cs], indexing="ij")
    return ndimage.map_coordinates(r.data.astype(np.float32, copy=False), [rr, cc], order=1, mode="constant",
                                   cval=np.nan, prefilter=False)


def _z_at(r: Raster, grid: GridSpec, rows: np.ndarray, cols: np.ndarray, dx: float = 0.0, dy: float = 0.0) -> np.ndarray:
    """:func:`kitegully.change.dod.resample` at the cells ``(rows, cols)`` of ``grid`` only (float32)."""
    if grid == r.grid and dx == 0.0 and dy == 0.0:
        return r.data[rows, cols].astype(np.float32)
    xs, ys = grid.cell_centres()
    rr, _ = r.grid.rowcol(np.zeros(1), ys + dy)
    _, cc = r.grid.rowcol(xs + dx, np.zeros(1))
    return ndimage.map_coordinates(r.data.astype(np.float32, copy=False), [rr[rows], cc[cols]], order=1, mode="constant",
                                   cval=np.nan, prefilter=False)


def _plane(co: Mapping[str, float], x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The co-registration plane at map coordinates (float32; the same arithmetic for a window and for points)."""
    return (co["dz_m"] + co["tilt_x"] * (x - co["x_centre"]) + co["tilt_y"] * (y - co["y_centre"])).astype(np.float32)


def _plane_window(co: Mapping[str, float], grid: GridSpec, rs: slice, cs: slice) -> np.ndarray:
    xs, ys = grid.cell_centres()
    return _plane(co, xs[None, cs], ys[rs, None])


def _sigma_window(epoch: Epoch, value: float | None, grid: GridSpec, rs: slice, cs: slice) -> np.ndarray | float:
    if value is not None:
        return value
    return resample_window(Raster.read(epoch.accuracy["error_raster"]), grid, rs, cs)


# ----------------------------------------------------------------------------- rules


def plan_change(epochs: Sequence[Mapping[str, Any]], out_json: str | Path, site_crs: str | None = None,
                checkpoint_outlier_nmad: float | None = 4.0) -> dict[str, Any]:
    """Rule ``change_plan``: the highest epoch-1 elevation and both epochs' σ (number or raster) with their sources.

    O(cells): both DEMs on the common grid once (as the untiled stage).

    Parameters
    ----------
    epochs : sequence of mapping
        Two epoch specs (older first): ``name, dem, nodata, accuracy``.
    out_json : str or Path
        The plan to write (JSON); its folder is created.
    site_crs : str or None
        The DEMs must be in this CRS.
    checkpoint_outlier_nmad : float or None
        Blunder rule of a σ from checkpoints (:func:`kitegully.change.uncertainty.epoch_sigma`).

    Returns
    -------
    dict
        The plan: ``z1_max`` (m), ``shape`` of the common grid, ``sigma`` (m per epoch, None for an error
        raster) and ``sigma_info``.
    """
    e1, e2, _ = _load(epochs, site_crs)
    grid, z1, z2 = on_common_grid(e1, e2)
    del z2
    plan: dict[str, Any] = {"z1_max": float(np.nanmax(z1)), "shape": [grid.height, grid.width], "sigma": [], "sigma_info": []}
    del z1
    for e in (e1, e2):
        s, info = unc.epoch_sigma(e, grid, checkpoint_outlier_nmad)
        plan["sigma"].append(float(s) if np.ndim(s) == 0 else None)
        plan["sigma_info"].append({k: (v.item() if isinstance(v, np.generic) else v) for k, v in info.items()})
    Path(out_json).parent.mkdir(parents=True, exist_ok=True)
    Path(out_json).write_text(json.dumps(plan, indent=2))
    log.info("change plan: grid %d x %d, epoch-1 maximum %.2f m, sigma %s", grid.height, grid.width, plan["z1_max"], plan["sigma"])
    return plan


def _tile_surfaces(epochs: Sequence[Mapping[str, Any]], site_crs: str | None, tiling: TilingParams, name: str,
                   params: ChangeParams, halo_index: int) -> tuple[Any, ...]:
    """Both epochs on tile ``name``'s window (halo ``halos(...)[halo_index]``), before co-registration.

    Returns ``e1, e2, grid, tile, rows, cols, core_rows, core_cols, z1, z2, window grid, matching voids``.
    """
    e1, e2, grid = _load(epochs, site_crs)
    t, rs, cs, cr, cc = _window(grid, tiling, name, halos(params, grid.cell)[halo_index])
    z1 = resample_window(e1.dem, grid, rs, cs)
    z2 = resample_window(e2.dem, grid, rs, cs)
    gw = grid.window(rs.start, cs.start, z1.shape[0], z1.shape[1])
    voids = matching_voids((e1, e2), gw, params.min_correlation, params.void_margin_m, valid=np.isfinite(z1) & np.isfinite(z2))
    return e1, e2, grid, t, rs, cs, cr, cc, z1, z2, gw, voids


def _tile_predictors(z1: np.ndarray, grid: GridSpec, params: ChangeParams, plan: Mapping[str, Any]) -> list[np.ndarray]:
    """The error model's predictors of a tile's read window (its halo covers their footprint: :func:`halos`)."""
    return em.terrain_predictors(z1, grid.cell, params.headcut_window_m, params.stable_object_window_m, fill=plan["z1_max"])


def _error_model_samples(e1: Epoch, e2: Epoch, z1: np.ndarray, unchanged: np.ndarray, grid: GridSpec, t: Any,
                         cr: slice, cc: slice, params: ChangeParams, plan: Mapping[str, Any]) -> dict[str, np.ndarray]:
    """The tile core's unchanged lattice cells (global row, col) and predictors, and the predictors at its checkpoints."""
    preds = [v[cr, cc] for v in _tile_predictors(z1, grid, params, plan)]
    k = em.lattice_step(int(plan["shape"][0]) * int(plan["shape"][1]))
    rows = np.arange(t.r0, t.r0 + t.h)[:, None]
    cols = np.arange(t.c0, t.c0 + t.w)[None, :]
    sel = unchanged[cr, cc] & (rows % k == 0) & (cols % k == 0)
    r, c = np.nonzero(sel)
    out = {"em_rows": r + t.r0, "em_cols": c + t.c0, **{f"em_p{i}": v[sel] for i, v in enumerate(preds)}}
    cps = em.checkpoint_cells((e1, e2), grid)
    if cps is not None:
        inside = (cps[0] >= t.r0) & (cps[0] < t.r0 + t.h) & (cps[1] >= t.c0) & (cps[1] < t.c0 + t.w)
        for i, v in enumerate(preds):
            out[f"em_cp{i}"] = v[cps[0][inside] - t.r0, cps[1][inside] - t.c0]
    return out


def _fit_tiled_error_model(stable_files: Sequence[str | Path], e1: Epoch, e2: Epoch, grid: GridSpec,
                           co: Mapping[str, Any]) -> em.ErrorModel | None:
    """The untiled error model from the tiles' lattice cells: DoD at those cells with the fitted co-registration."""
    parts: dict[str, list[np.ndarray]] = {}
    for f in stable_files:
        with np.load(f) as z:
            for k in z.files:
                if k.startswith("em_"):
                    parts.setdefault(k, []).append(z[k])
    cat = {k: np.concatenate(v) for k, v in parts.items()}
    rr, cc = cat["em_rows"], cat["em_cols"]
    z1 = _z_at(e1.dem, grid, rr, cc)
    if co["applied"]:
        xs, ys = grid.cell_centres()
        z2 = _z_at(e2.dem, grid, rr, cc, co["dx_m"], co["dy_m"]) - _plane(co, xs[cc], ys[rr])
    else:
        z2 = _z_at(e2.dem, grid, rr, cc)
    dod = dem_of_difference(z1, z2)
    n = len(em.PREDICTORS)
    model = em.fit_error_model(dod, [cat[f"em_p{i}"] for i in range(n)], np.ones(dod.shape, bool))
    if model is not None and "em_cp0" in cat and cat["em_cp0"].size:
        model.refer_to([cat[f"em_cp{i}"] for i in range(n)])
    return model


def stable_tile(epochs: Sequence[Mapping[str, Any]], masks: Sequence[Mapping[str, Any]], plan_json: str | Path,
                params: ChangeParams, tiling: TilingParams, name: str, out_npz: str | Path,
                site_crs: str | None = None) -> int:
    """Rule ``change_stable_tile``: stable ground, co-registration candidates and dh before co-registration of one tile.

    Returns the tile's stable cells. O(window cells · object window).

    Parameters
    ----------
    epochs : sequence of mapping
        Two epoch specs (older first).
    masks : sequence of mapping
        Budget mask specs.
    plan_json : str or Path
        The ``change_plan`` JSON.
    params : ChangeParams
        The stage's parameters.
    tiling : TilingParams
        The site's tiling.
    name : str
        The tile's name, e.g. ``r000_c000``.
    out_npz : str or Path
        Archive to write: the core's ``stable``, ``base`` (candidates) and ``dh``, its origin ``r0, c0`` and,
        with ``heteroscedastic``, the error model's samples.
    site_crs : str or None
        The DEMs must be in this CRS.

    Returns
    -------
    int
        Number of stable cells in the tile's core.
    """
    plan = json.loads(Path(plan_json).read_text())
    e1, e2, grid, t, rs, cs, cr, cc, z1, z2, gw, voids = _tile_surfaces(epochs, site_crs, tiling, name, params, 0)
    groups = bg.mask_groups(masks, gw)
    unstable = bg.unstable_union(masks, groups, z1.shape)
    unchanged = np.isfinite(z1) & ~unstable & ~voids
    stable = np.isfinite(z1) & ~voids & bg.stable_candidates(masks, groups, z1.shape, unstable)
    if params.stable_max_object_height_m is not None:
        stable &= ~above_ground(z1, grid.cell, params.stable_object_window_m, params.stable_max_object_height_m,
                                fill=plan["z1_max"])
    gy, gx = np.gradient(z1.astype(np.float64), grid.cell)
    tan_a = np.hypot(gx, -gy)
    base = stable & np.isfinite(z1) & np.isfinite(tan_a) & (tan_a <= np.tan(np.radians(params.coreg_max_slope_deg)))
    dh = np.where(stable, z2 - z1, np.nan)
    extra = _error_model_samples(e1, e2, z1, unchanged, grid, t, cr, cc, params, plan) if params.heteroscedastic else {}
    Path(out_npz).parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(out_npz, stable=stable[cr, cc], base=base[cr, cc], dh=dh[cr, cc], r0=t.r0, c0=t.c0, **extra)
    n = int(stable[cr, cc].sum())
    log.info("tile %s: %d x %d cells, %.1f %% stable ground", name, t.h, t.w, 100.0 * n / max(t.h * t.w, 1))
    return n


def _assemble(files: Sequence[str | Path], shape: tuple[int, int], keys: Mapping[str, tuple[Any, Any]]) -> dict[str, np.ndarray]:
    """Whole-grid arrays from the tiles' cores (``keys``: name -> (dtype, fill)); every cell exactly once."""
    out = {k: np.full(shape, fill, dtype) for k, (dtype, fill) in keys.items()}
    seen = np.zeros(shape, np.uint8)
    for f in files:
        with np.load(f) as z:
            r0, c0 = int(z["r0"]), int(z["c0"])
            h, w = z[next(iter(keys))].shape
            for k in keys:
                out[k][r0:r0 + h, c0:c0 + w] = z[k]
        seen[r0:r0 + h, c0:c0 + w] += 1
    if not (seen == 1).all():
        raise InputError(f"{files[0]}: the change tiles do not cover the common grid exactly once")
    return out


def coregister_tiles(stable_files: Sequence[str | Path], epochs: Sequence[Mapping[str, Any]], params: ChangeParams,
                     out_json: str | Path, site_crs: str | None = None) -> Coregistration:
    """Rule ``change_coregister``: the global shift + plane fit on the sampled stable cells of all tiles.

    The sample is the untiled one (every ``n/coreg_max_samples``-th candidate cell in row-major
    order of the whole grid); slopes and DEM₂ are evaluated at the sampled cells only.
    O(cells) bytes for the masks; O(iterations × samples) for the fit.

    Parameters
    ----------
    stable_files : sequence of str or Path
        The ``change_stable_tile`` archives of all tiles.
    epochs : sequence of mapping
        Two epoch specs (older first).
    params : ChangeParams
        The stage's parameters.
    out_json : str or Path
        Record to write (JSON): the fit's fields, ``applied`` and, with ``heteroscedastic``, ``error_model``.
    site_crs : str or None
        The DEMs must be in this CRS.

    Returns
    -------
    Coregistration
        The fit with its ``before`` statistics; ``after`` is left empty.
    """
    e1, e2, grid = _load(epochs, site_crs)
    shape = (grid.height, grid.width)
    a = _assemble(stable_files, shape, {"stable": (bool, False), "base": (bool, False), "dh": (np.float32, np.nan)})
    xs, ys = grid.cell_centres()
    info = Coregistration(x_centre=float(xs.mean()), y_centre=float(ys.mean()))
    info.before = residual_stats(a.pop("dh"))
    applied = False
    if params.coreg_enabled:
        idx = _sample(np.flatnonzero(a["base"]), params.coreg_max_samples)
        if idx.size < 100:
            log.warning("only %d stable cells: co-registration skipped", idx.size)
        else:
            rr, cc = np.unravel_index(idx, shape)
            H, W = shape
            cm, cp = np.maximum(cc - 1, 0), np.minimum(cc + 1, W - 1)
            rm, rp = np.maximum(rr - 1, 0), np.minimum(rr + 1, H - 1)
            z = lambda r, c: _z_at(e1.dem, grid, r, c).astype(np.float64)  # noqa: E731
            gx = (z(rr, cp) - z(rr, cm)) / ((cp - cm) * grid.cell)  # np.gradient, central inside, one-sided at the edges
            gy = -((z(rp, cc) - z(rm, cc)) / ((rp - rm) * grid.cell))
            fit_shift_plane(info, _z_at(e1.dem, grid, rr, cc), gx, gy, np.hypot(gx, gy), xs[cc] - info.x_centre,
                            ys[rr] - info.y_centre, lambda dx, dy: _z_at(e2.dem, grid, rr, cc, dx, dy), params)
            applied = True
    rec = {k: v for k, v in info.as_dict().items() if k not in ("after", "offset_sd_m")}
    rec["applied"] = applied
    if params.heteroscedastic:
        model = _fit_tiled_error_model(stable_files, e1, e2, grid, rec)
        rec["error_model"] = model.to_json() if model is not None else None
    Path(out_json).write_text(json.dumps(rec, indent=2, default=float))
    log.info("co-registration from %d tiles: shift (%.3f, %.3f) m, dz %.3f m (applied: %s)", len(stable_files),
             info.dx_m, info.dy_m, info.dz_m, applied)
    return info


def change_tile(epochs: Sequence[Mapping[str, Any]], masks: Sequence[Mapping[str, Any]], plan_json: str | Path,
                coreg_json: str | Path, stable_npz: str | Path, params: ChangeParams, tiling: TilingParams, name: str,
                out_npz: str | Path, site_crs: str | None = None) -> None:
    """Rule ``change_tile``: DoD, σ_DoD, thresholds and the budget rows' partial sums of one tile.

    O(window cells · masks).

    Parameters
    ----------
    epochs : sequence of mapping
        Two epoch specs (older first).
    masks : sequence of mapping
        Budget mask specs.
    plan_json : str or Path
        The ``change_plan`` JSON.
    coreg_json : str or Path
        The ``change_coregister`` JSON.
    stable_npz : str or Path
        This tile's ``change_stable_tile`` archive.
    params : ChangeParams
        The stage's parameters.
    tiling : TilingParams
        The site's tiling.
    name : str
        The tile's name, e.g. ``r000_c000``.
    out_npz : str or Path
        Archive to write: the core's rasters and detections, the void count and the budget rows' sums.
    site_crs : str or None
        The DEMs must be in this CRS.
    """
    plan = json.loads(Path(plan_json).read_text())
    co = json.loads(Path(coreg_json).read_text())
    e1, e2, grid, t, rs, cs, cr, cc, z1, z2, gw, voids = _tile_surfaces(epochs, site_crs, tiling, name, params, 1)
    if co["applied"]:
        z2 = resample_window(e2.dem, grid, rs, cs, co["dx_m"], co["dy_m"]) - _plane_window(co, grid, rs, cs)
    dod = dem_of_difference(z1, z2)
    n_void = int((voids & np.isfinite(dod))[cr, cc].sum())
    dod[voids] = np.nan
    s1 = _sigma_window(e1, plan["sigma"][0], grid, rs, cs)
    s2 = _sigma_window(e2, plan["sigma"][1], grid, rs, cs)
    sigma = unc.propagate(s1, s2, dod.shape)
    factor = None
    if co.get("error_model"):
        factor = em.ErrorModel.from_json(co["error_model"]).factor(_tile_predictors(z1, grid, params, plan))
        sigma = (sigma * factor).astype(np.float32)
    detected = unc.detect(dod, sigma, params)
    with np.load(stable_npz) as z:
        if (int(z["r0"]), int(z["c0"])) != (t.r0, t.c0):
            raise InputError(f"{stable_npz}: stable ground of another tile than {name}")
        stable0 = z["stable"]
    dod, sigma = dod[cr, cc], sigma[cr, cc]
    detected = {m: d[cr, cc] for m, d in detected.items()}
    groups = bg.mask_groups(masks, grid.window(t.r0, t.c0, t.h, t.w))
    spec_of = {s["name"]: i for i, s in enumerate(masks)}
    valid = np.isfinite(dod)
    sums = np.zeros((len(groups), len(METHODS), 4))
    area = np.zeros(len(groups), np.int64)
    for i, g in enumerate(groups):
        inside = g.local & g.block(valid)
        area[i] = int(inside.sum())
        d, sg = g.block(dod), g.block(sigma)
        for j, (m, det) in enumerate([("raw", valid), *detected.items()]):
            sums[i, j] = bg.budget_sums(d, sg, inside & g.block(det))
    order = np.array([[-1 if g.name == "site" else spec_of[g.name.split(":")[0]], g.order] for g in groups], float)
    np.savez_compressed(out_npz, r0=t.r0, c0=t.c0, z1=z1[cr, cc], z2=z2[cr, cc].astype(np.float32), dod=dod, sigma=sigma,
                        **({} if factor is None else {"factor": factor[cr, cc]}), stable0=stable0, **{f"det_{m}": d for m, d in detected.items()}, n_void=n_void,
                        names=np.array([g.name for g in groups]), order=order, sums=sums, area=area)
    log.info("tile %s: DoD of %d valid cells, %d void cells", name, int(valid.sum()), n_void)


def budgets_from_tiles(tile_files: Sequence[str | Path], cell: float, vg: Any, coreg_sd_m: float) -> pd.DataFrame:
    """The budget table from the tiles' partial sums, rows in the untiled order (site, then each mask's rows).

    Parameters
    ----------
    tile_files : sequence of str or Path
        The ``change_tile`` archives.
    cell : float
        Cell size (m).
    vg : Variogram or None
        Model of the standardised dh; None gives a NaN correlated SD.
    coreg_sd_m : float
        SD of the co-registration's vertical offset (m).

    Returns
    -------
    DataFrame
        The columns of :func:`kitegully.change.budget.compute_budgets`.
    """
    import pandas as pd

    acc: dict[str, list] = {}
    for f in tile_files:
        with np.load(f) as z:
            for name, order, s, n in zip(z["names"], z["order"], z["sums"], z["area"]):
                name = str(name)
                if name not in acc:
                    acc[name] = [tuple(order), np.zeros_like(s), 0]
                acc[name][1] = acc[name][1] + s
                acc[name][2] += int(n)
    rows = []
    for name, (_, s, n) in sorted(acc.items(), key=lambda kv: kv[1][0]):
        for j, m in enumerate(METHODS):
            row = dict(mask=name, method=m, mask_area_m2=float(n * cell * cell))
            row.update(bg.budget_row_from_sums((int(s[j, 0]), float(s[j, 1]), float(s[j, 2]), float(s[j, 3])), cell, vg, coreg_sd_m))
            rows.append(row)
    cols = ["mask", "method", "erosion_m3", "deposition_m3", "net_m3", "net_sd_m3", "net_sd_independent_m3",
            "net_sd_correlated_m3", "net_sd_coregistration_m3", "area_m2", "mask_area_m2", "mean_dh_m"]
    return pd.DataFrame(rows)[cols]


def merge_change(tile_files: Sequence[str | Path], plan_json: str | Path, coreg_json: str | Path,
                 epochs: Sequence[Mapping[str, Any]], heads_path: str | None, params: ChangeParams,
                 out: Mapping[str, str], site_crs: str | None = None, figure: Mapping[str, Any] | None = None,
                 attribution: str | None = None, sections_path: str | None = None) -> dict[str, Any]:
    """Rule ``change_merge``: every product of :func:`kitegully.change.stage.detect_change` from the tiles.

    Returns the same summary. O(cells) to write the rasters; the budgets O(tiles × rows).

    Parameters
    ----------
    tile_files : sequence of str or Path
        The ``change_tile`` archives of all tiles.
    plan_json, coreg_json : str or Path
        The ``change_plan`` and ``change_coregister`` JSONs.
    epochs : sequence of mapping
        Two epoch specs (older first).
    heads_path : str or None
        GeoPackage of heads digitised at epoch 1, or None.
    params : ChangeParams
        The stage's parameters.
    out : mapping
        Output paths by key (:data:`kitegully.change.params.OUTPUTS` and ``thresholded_<method>``).
    site_crs : str or None
        The DEMs must be in this CRS.
    figure : mapping or None
        ``limit_m`` and ``max_px`` of the figures.
    attribution : str or None
        Data attribution printed on the figures; None prints none.
    sections_path : str or None
        Epoch-1 cross-sections whose width is measured on both DEMs, or None.

    Returns
    -------
    dict
        The summary of :func:`kitegully.change.stage.detect_change`, plus ``tiles`` (the number of tiles).
    """

    from rasterio.crs import CRS

    t0 = time.perf_counter()
    import rasterio

    from kitegully.io.raster import grid_of

    with rasterio.open(epochs[0]["dem"]) as a, rasterio.open(epochs[1]["dem"]) as b:
        grid = overlap_grid(grid_of(a, epochs[0]["dem"]), grid_of(b, epochs[1]["dem"]), epochs[0]["dem"], epochs[1]["dem"])
    if site_crs is not None and CRS.from_user_input(grid.crs) != CRS.from_user_input(site_crs):
        raise InputError(f"{epochs[0]['dem']}: CRS {grid.crs} differs from the site CRS {site_crs}")
    plan = json.loads(Path(plan_json).read_text())
    co = json.loads(Path(coreg_json).read_text())
    keys = {"z1": (np.float32, np.nan), "z2": (np.float32, np.nan), "dod": (np.float32, np.nan),
            "sigma": (np.float32, np.nan), "stable0": (bool, False), **{f"det_{m}": (bool, False) for m in THRESHOLD_METHODS}}
    model = em.ErrorModel.from_json(co["error_model"]) if co.get("error_model") else None
    if model is not None:  # the factor grid only where the tiles applied one
        keys["factor"] = (np.float32, 1.0)
    a = _assemble(tile_files, (grid.height, grid.width), keys)
    z1, z2, dod, sigma = a["z1"], a["z2"], a["dod"], a["sigma"]
    n_void = 0
    for f in tile_files:
        with np.load(f) as z:
            n_void += int(z["n_void"])
    stable = a["stable0"] & np.isfinite(dod)
    sigma_rows = list(plan["sigma_info"])
    if params.heteroscedastic:
        sigma_rows.append(em.factor_row(model, a.pop("factor", None), dod))
    coreg = Coregistration(**{k: v for k, v in co.items() if k not in ("applied", "error_model")})
    coreg.after = residual_stats(np.where(a["stable0"], z2 - z1, np.nan)) if co["applied"] else coreg.before
    del a["stable0"]
    Raster(dod, grid).write(out["dod"], tags={"units": "m", "definition": "DEM2 (co-registered) - DEM1"})
    Raster(sigma, grid).write(out["sigma_dod"], tags={"units": "m", "definition": "sqrt(s1^2 + s2^2)" + (
        em.SIGMA_FACTOR_TAG if params.heteroscedastic else "")})
    Raster(stable.astype(np.uint8), grid, 255).write(out["stable"], tags={"definition": "1 = stable ground used for co-registration"})
    for m in THRESHOLD_METHODS:
        Raster(unc.thresholded(dod, a.pop(f"det_{m}")), grid).write(out[f"thresholded_{m}"], tags={"units": "m", "threshold": m})
    vg, coreg_sd = uncertainty_model(dod, sigma, stable, grid, params, out, attribution)
    coreg.offset_sd_m = coreg_sd
    budget = budgets_from_tiles(tile_files, grid.cell, vg, coreg_sd)
    top = [m for m in dict.fromkeys(budget["mask"]) if ":" not in m]
    summary = write_products(budget, coreg, sigma_rows, sigma, n_void, grid, z1, z2, dod, stable, heads_path,
                             sections_path, params, out, top, figure, attribution, t0)
    summary["tiles"] = len(tile_files)
    return summary
