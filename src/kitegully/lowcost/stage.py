"""The ``lowcost`` stage (issue 18, paper 004): entry points named after what they make.

- :func:`measure_spectral_response`: camera responses from a simulated ColorChecker shot.
- :func:`survey_lowcost`: joint RGB+NIR SfM, tape/Horn/tide georeferencing (and the RTK
  comparison block), DSM, white-balanced RGB and NIR mosaics, NDVI, ExG, slope, aspect.
- :func:`evaluate_lowcost`: NDVI per cover class and bare-ground indicators against the
  twin's truth, target errors of both georeferencings (evaluation only).
"""

from __future__ import annotations

import json
import logging
import sqlite3
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping

import numpy as np
import pandas as pd
from PIL import Image
from scipy.interpolate import LinearNDInterpolator

from kitegully import InputError
from kitegully.config import config_section
from kitegully.evaluate.dem import nmad
from kitegully.io.raster import GridSpec, Raster, read_raster
from kitegully.io.tables import write_table
from kitegully.lowcost import spectral as sp
from kitegully.lowcost.georef import (georeference_rtk, georeference_tape_horn, read_points, read_tape,
                                      triangulate)
from kitegully.lowcost.surface import slope_aspect
from kitegully.obia.indices import excess_green, ndvi
from kitegully.seeds import rng_for

if TYPE_CHECKING:
    from collections.abc import Collection

log = logging.getLogger(__name__)

PAPER_MATCHES = {"RGB-RGB": (4454, 854.6), "RGB-NIR": (3063, 188.2), "NIR-NIR": (2630, 1106.2)}
MAX_IMAGE_ID = 2147483647   # COLMAP: pair_id = id1 * MAX + id2


@dataclass(frozen=True)
class SurveyParams:
    """The ``lowcost.survey`` section.

    Attributes
    ----------
    gamma : float
        Tone curve of the cameras' JPEGs, ``DN = 255 signal^(1/gamma)``: mosaics are
        linearised before white balance (the paper's raw files are linear already).
    dsm_cell_m : float
        Cell of the DSM sampled from the Delaunay TIN of the tie points [I] 0.1 m, about
        the tie-point spacing.
    ortho_upsample : int
        Mosaic cells per DSM cell side [I] 5: 2 cm, the photos' GSD.
    min_track_length : int
        Tie points seen in fewer photos are left out of the TIN [I] 3.
    occlusion_tolerance_m : float
        Orthophoto occlusion test tolerance (m).
    level_to_water : bool
        [I] Also level the model on the waterline (the water is a level surface), not only
        shift it (the paper): GPS heights of ±2 m over a 24 m target spread leave a tilt of
        several degrees in Horn's rotation. The products use the levelled block when true;
        both blocks are reported.
    waterline_min_spread_m : float
        [I] Across-waterline spread (SD, m) below which only the along-line tilt is fixed
        (1 m: a 2 m band of points resolves a tilt to a few cm/m with 1.5 px clicks).
    dsm_method : str
        ``tin`` (the Delaunay TIN of the tie points, paper 004's PMVS+TIN reduced to the
        sparse cloud) or ``dense``: the dense stage's object-space matcher
        (:func:`kitegully.dense.surface.dense_surface`) on the RGB photos of the
        georeferenced block, on the same grid; cells it masks (textureless water,
        occlusions) take the TIN's height, as the paper's TIN bridges PMVS's gaps. Both
        DSMs are written (``dsm_tin.tif``, ``dsm_dense.tif``); ``dsm.tif`` is the chosen one.
    dense : dict or None
        With ``dsm_method: dense``: ``tile_cells``, ``overlap_cells``, ``max_cached_images``
        and ``matching`` (the dense stage's ``dense.matching`` keys,
        :class:`kitegully.dense.matching.MatchParams`).
    """

    gamma: float
    dsm_cell_m: float
    ortho_upsample: int
    min_track_length: int
    occlusion_tolerance_m: float
    level_to_water: bool
    waterline_min_spread_m: float
    dsm_method: str = "tin"
    dense: Any = None

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any]) -> "SurveyParams":
        """Build from ``lowcost.survey`` (``dense`` with ``dsm_method: dense``); raises InputError naming a bad key."""
        config_section(cfg, "lowcost.survey", [k for k in cls.__dataclass_fields__ if k != "dense"], optional=("dense",))
        if cfg["dsm_method"] not in ("tin", "dense"):
            raise InputError(f"lowcost.survey.dsm_method: must be tin or dense, got {cfg['dsm_method']!r}")
        dense = None
        if cfg["dsm_method"] == "dense":
            from kitegully.dense.matching import MatchParams
            if cfg.get("dense") is None:
                raise InputError("lowcost.survey.dense: dsm_method dense needs the dense section (tile_cells, overlap_cells, "
                                 "max_cached_images, matching)")
            d = config_section(cfg["dense"], "lowcost.survey.dense", ["tile_cells", "overlap_cells", "max_cached_images", "matching"])
            config_section(d["matching"], "lowcost.survey.dense.matching", MatchParams.REQUIRED,
                           optional=MatchParams.OPTIONAL)
            dense = {"tile_cells": int(d["tile_cells"]), "overlap_cells": int(d["overlap_cells"]),
                     "max_cached_images": int(d["max_cached_images"]), "matching": MatchParams.from_config(d["matching"])}
        for k in ("gamma", "dsm_cell_m", "ortho_upsample", "occlusion_tolerance_m"):
            if not float(cfg[k]) > 0:
                raise InputError(f"lowcost.survey.{k}: must be positive, got {cfg[k]!r}")
        if not isinstance(cfg["level_to_water"], bool):
            raise InputError(f"lowcost.survey.level_to_water: must be true or false, got {cfg['level_to_water']!r}")
        return cls(float(cfg["gamma"]), float(cfg["dsm_cell_m"]), int(cfg["ortho_upsample"]),
                   int(cfg["min_track_length"]), float(cfg["occlusion_tolerance_m"]), cfg["level_to_water"],
                   float(cfg["waterline_min_spread_m"]), str(cfg["dsm_method"]), dense)


# --------------------------------------------------------------------------- spectral


def measure_spectral_response(cfg: Mapping[str, Any], seed: int, csv_path: str | Path, peaks_path: str | Path,
                              png_path: str | Path) -> pd.DataFrame:
    """Recover the RGB and NIR-converted cameras' responses from ``draws`` noisy chart calibrations.

    A calibration is one shot of the chart per illuminant (``illuminants``), each the mean
    of ``frames_per_shot`` raw frames, solved together (:func:`spectral.stack_shots`).
    Writes the curves of the first draw with the truth (``csv_path``), the peak statistics
    over all draws (``peaks_path``) and a figure. Returns the peak table. O(draws x
    lambdas x n_wl^3), a few seconds.

    Parameters
    ----------
    cfg : mapping
        The ``lowcost.spectral`` section: the :class:`spectral.SpectralParams` keys and ``draws``.
    seed : int
        The run's seed (one noise stream per draw and illuminant).
    csv_path : path
        Table of the true and first draw's recovered curves.
    peaks_path : path
        Table of the peak statistics.
    png_path : path
        Figure of the curves.

    Returns
    -------
    DataFrame
        One row per channel (red, green, blue, nir): true, recovered and paper peaks (nm),
        peak errors (nm) and mean RMS curve error.
    """
    config_section(cfg, "lowcost.spectral", ["wl_min_nm", "wl_max_nm", "wl_step_nm", "illuminants", "relative_noise",
                                             "frames_per_shot", "draws"])
    p = sp.SpectralParams.from_config(cfg)
    w = p.wavelengths
    _, refl = sp.chart_reflectance(w)
    designs = [sp.chart_design(refl, sp.illuminant(i, w), p.wl_step_nm) for i in p.illuminants]
    true = np.column_stack([sp.rgb_response(w), sp.nir_converted_response(w)])
    names = ["red", "green", "blue", "nir"]
    peaks, errs, first = [], [], None
    for d in range(int(cfg["draws"])):
        shots = [sp.simulate_averaged_shot(A, true, p.relative_noise, p.frames_per_shot,
                                           rng_for(seed, "lowcost", "chart", d, i))
                 for i, A in zip(p.illuminants, designs)]
        A3, v = sp.stack_shots(designs, shots)
        rec, _ = sp.recover_response(A3, v, p.shot_noise, p.lambdas)
        first = rec if first is None else first
        peaks.append(sp.peak_wavelength(w, rec))
        errs.append(sp.curve_error(true, rec))
    peaks, errs = np.array(peaks), np.array(errs)
    tp = sp.peak_wavelength(w, true)
    table = pd.DataFrame({
        "channel": names, "true_peak_nm": tp, "recovered_peak_mean_nm": peaks.mean(0), "recovered_peak_sd_nm": peaks.std(0),
        "peak_error_mean_nm": peaks.mean(0) - tp, "peak_error_max_abs_nm": np.abs(peaks - tp).max(0),
        "curve_rms_error": errs.mean(0), "paper_peak_nm": [sp.PAPER_PEAKS_NM[n] for n in names]})
    curves = pd.DataFrame({"wavelength_nm": w})
    for i, n in enumerate(names):
        curves[f"{n}_true"] = true[:, i] / true[:, i].max()
        curves[f"{n}_recovered"] = first[:, i]
    write_table(curves, csv_path)
    write_table(table, peaks_path)
    from kitegully.io.figures import new_figure, save_figure
    fig, ax = new_figure(figsize=(7, 4))
    for n, col in zip(names, ("tab:red", "tab:green", "tab:blue", "0.3")):
        ax.plot(w, curves[f"{n}_true"], color=col, lw=1, ls="--", label=f"{n} true")
        ax.plot(w, curves[f"{n}_recovered"], color=col, lw=2, label=f"{n} recovered")
    ax.set_xlabel("wavelength (nm)")
    ax.set_ylabel("relative response (max = 1)")
    ax.set_title(f"Camera spectral response from ColorChecker shots under {', '.join(p.illuminants)} (smooth NNLS)")
    ax.legend(fontsize=7, ncol=2)
    save_figure(fig, png_path)
    return table


# --------------------------------------------------------------------------- SfM


def matches_by_pair_type(database: str | Path, sfm_to_name: Mapping[str, str], min_num_matches: int) -> pd.DataFrame:
    """Verified (two-view geometry inlier) matches per image pair, by sensor pair type.

    The paper's table counts pairs that matched and their mean matches; pairs with at least
    ``min_num_matches`` inliers are counted here. O(pairs).

    Parameters
    ----------
    database : path
        COLMAP database of the SfM run.
    sfm_to_name : mapping
        SfM image name to original image name; a name starting with ``nir`` marks a NIR photo.
    min_num_matches : int
        Fewest inlier matches for a pair to count as matched.

    Returns
    -------
    DataFrame
        One row per pair type (RGB-RGB, RGB-NIR, NIR-NIR): pairs tested, pairs matched, mean
        matches per matched pair and the paper's values.
    """
    con = sqlite3.connect(str(database))
    try:
        names = dict(con.execute("SELECT image_id, name FROM images").fetchall())
        geo = con.execute("SELECT pair_id, rows FROM two_view_geometries").fetchall()
    finally:
        con.close()

    def sensor(image_id: int) -> str:
        n = sfm_to_name.get(names[image_id], names[image_id])
        return "NIR" if Path(n).name.lower().startswith("nir") else "RGB"

    n_by = {"RGB": sum(1 for i in names if sensor(i) == "RGB"), "NIR": sum(1 for i in names if sensor(i) == "NIR")}
    counts: dict[str, list[int]] = {k: [] for k in PAPER_MATCHES}
    for pair_id, rows in geo:
        i2 = pair_id % MAX_IMAGE_ID
        i1 = (pair_id - i2) // MAX_IMAGE_ID
        a, b = sorted((sensor(i1), sensor(i2)), key=lambda s: s != "RGB")
        if rows >= min_num_matches:
            counts[f"{a}-{b}"].append(int(rows))
    out = []
    for k, v in counts.items():
        a, b = k.split("-")
        all_pairs = n_by[a] * (n_by[a] - 1) // 2 if a == b else n_by[a] * n_by[b]
        out.append({"pair_type": k, "pairs_tested": all_pairs, "pairs_matched": len(v),
                    "mean_matches_per_matched_pair": float(np.mean(v)) if v else 0.0,
                    "paper_pairs_matched": PAPER_MATCHES[k][0], "paper_mean_matches": PAPER_MATCHES[k][1]})
    return pd.DataFrame(out)


def check_nir_images(images_dir: str | Path, prefix: str = "nir") -> None:
    """Every NIR photo must carry a red channel (the NIR-converted camera's NIR band).

    Raises
    ------
    InputError
        Naming the first NIR photo with fewer than 3 channels.
    """
    for path in sorted(Path(images_dir).glob(f"{prefix}*")):
        with Image.open(path) as im:
            if len(im.getbands()) < 3:
                raise InputError(f"{path}: NIR photo has no red channel (mode {im.mode}, {len(im.getbands())} band); "
                                 "the NIR-converted camera's NIR is read from the red channel of an RGB file")


def _transform_views(views, sim, offset):
    """Views and tie points in the site CRS: ``X_world = s R X_model + t``."""
    from kitegully.dense.views import ViewSet
    imgs = [replace(im, R=im.R @ sim.R.T, C=sim.apply(im.C) - offset) for im in views.images]
    return ViewSet(imgs, offset, sim.apply(views.sparse_points) - offset)


def tin_dsm(points: np.ndarray, cell: float, crs: str) -> tuple[np.ndarray, GridSpec]:
    """DSM sampled from the 2-D Delaunay TIN of ``points`` (x, y, z) at ``cell`` (paper 004
    sect. 2.5, [I] Delaunay on x, y); NaN outside the hull. O(n log n + cells).

    Parameters
    ----------
    points : ndarray (n, 3)
        Points x, y, z in the site CRS (m).
    cell : float
        DSM cell size (m).
    crs : str
        Site CRS.

    Returns
    -------
    dsm : ndarray (H, W) float32
        Heights (m) of the TIN at the cell centres.
    grid : GridSpec
        Grid covering the 0.5–99.5 percentile range of the points' x and y.
    """
    lo = np.percentile(points[:, :2], 0.5, axis=0)
    hi = np.percentile(points[:, :2], 99.5, axis=0)
    grid = GridSpec.covering((lo[0], lo[1], hi[0], hi[1]), cell, crs)
    xs, ys = np.meshgrid(*grid.cell_centres())
    o = points[:, :2].mean(axis=0)
    f = LinearNDInterpolator(points[:, :2] - o, points[:, 2])
    return f(xs - o[0], ys - o[1]).astype(np.float32), grid


def white_balance(dn: np.ndarray, panel_dn: np.ndarray, panel_reflectance: float, gamma: float) -> np.ndarray:
    """Reflectance of each channel: linearised DN over the linearised Spectralon DN shot at
    the same settings, times the panel's reflectance; DN 0 (no data) becomes NaN.

    Parameters
    ----------
    dn : ndarray (B, H, W) uint8
        Mosaic digital numbers, 0 = no data.
    panel_dn : ndarray (B,)
        Mean DN of the Spectralon panel in each channel.
    panel_reflectance : float
        Reflectance of the panel (0–1).
    gamma : float
        Tone curve exponent of the JPEGs, ``DN = 255 signal^(1/gamma)``.

    Returns
    -------
    ndarray (B, H, W) float32
        Reflectance of each channel, NaN where ``dn`` is 0.
    """
    lin = (dn.astype(np.float32) / 255.0) ** gamma
    ref = (np.asarray(panel_dn, np.float32) / 255.0) ** gamma
    out = lin / ref.reshape(-1, *([1] * (dn.ndim - 1))) * panel_reflectance
    out[dn == 0] = np.nan
    return out.astype(np.float32)


def survey_lowcost(observed_dir: str | Path, sfm_cfg: Mapping[str, Any], survey_cfg: Mapping[str, Any], seed: int,
                   crs: str, out_dir: str | Path, threads: int = 1) -> dict:
    """Run the paper's low-cost survey on the observed files of ``observed_dir``.

    Inputs (``observed_dir``): ``images/`` (``rgb_*`` and ``nir_*`` photos), ``image_clicks.csv``,
    ``targets_gps.csv``, ``targets_rtk.csv``, ``tape.csv``, ``water_level.json``,
    ``panel_shots.csv``. Outputs in ``out_dir``: ``sfm/`` (model, database), the tables
    ``matches_by_pair_type.csv`` and ``georef_residuals.csv``, ``georef.json`` and the rasters
    ``dsm.tif``, ``rgb_orthomosaic.tif``, ``nir_orthomosaic.tif``, ``ndvi.tif``, ``exg.tif``,
    ``slope.tif``, ``aspect.tif``. Returns the summary written to ``survey.json``.

    Cost: SfM dominates (exhaustive matching, O(images²)); mosaics O(cells x views).

    Parameters
    ----------
    observed_dir : path
        Folder of the observed files listed above.
    sfm_cfg : mapping
        The ``sfm`` section (:class:`kitegully.sfm.SfmParams`).
    survey_cfg : mapping
        The ``lowcost.survey`` section (:class:`SurveyParams`).
    seed : int
        The run's seed (SfM stream ``rng_for(seed, "lowcost", "sfm")``).
    crs : str
        Site CRS.
    out_dir : path
        Output folder, created if missing.
    threads : int
        Threads of the SfM.

    Returns
    -------
    dict
        Image, registration, point and target counts, reprojection error (px), timings (s),
        cell sizes (m) and the DSM method.
    """
    import pycolmap

    from kitegully.dense.ortho import orthophoto
    from kitegully.dense.views import views_from_reconstruction
    from kitegully.sfm import SfmParams, reconstruct_model
    from kitegully.sfm.stage import load_image_infos

    t0 = time.perf_counter()
    obs, out = Path(observed_dir), Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    sp_ = SurveyParams.from_config(survey_cfg)
    sfm = SfmParams.from_config(sfm_cfg)
    check_nir_images(obs / "images")
    gps = read_points(obs / "targets_gps.csv", "handheld-GPS targets")
    rtk = read_points(obs / "targets_rtk.csv", "RTK targets")
    edges = read_tape(obs / "tape.csv", set(gps))
    water = json.loads((obs / "water_level.json").read_text())["height_m"]
    work = out / "sfm"
    summary = reconstruct_model(obs / "images", work / "work", work / "model", work / "summary.json", work / "images.csv",
                                work / "image_info.json", sfm, int(rng_for(seed, "lowcost", "sfm").integers(2**31 - 1)),
                                threads)
    t_sfm = time.perf_counter() - t0
    infos = load_image_infos(work / "image_info.json")
    sfm_to_name = {i.sfm_name: i.name for i in infos}
    name_to_sfm = {v: k for k, v in sfm_to_name.items()}
    mt = matches_by_pair_type(work / "work" / "database.db", sfm_to_name, sfm.min_num_matches)
    write_table(mt, out / "matches_by_pair_type.csv")
    rec = pycolmap.Reconstruction(str(work / "model"))
    n_cams = len(rec.cameras)
    views = views_from_reconstruction(rec, work / "work" / "images", local_offset=np.zeros(3), where=str(work / "model"))
    by_name = {sfm_to_name[im.name]: im for im in views.images}
    clicks = pd.read_csv(obs / "image_clicks.csv")
    model_t = triangulate(clicks[clicks["kind"] == "target"], by_name)
    model_w = triangulate(clicks[clicks["kind"] == "waterline"], by_name)
    mw = np.array(list(model_w.values()))
    sim_shift, dz, res = georeference_tape_horn(model_t, gps, edges, mw, water)
    sim_level, dz_level, _ = georeference_tape_horn(model_t, gps, edges, mw, water, level=True,
                                                    min_spread_m=sp_.waterline_min_spread_m)
    sim = sim_level if sp_.level_to_water else sim_shift
    sim_rtk, res_rtk = georeference_rtk(model_t, rtk, edges)
    residuals = pd.concat([res, res_rtk], ignore_index=True)
    write_table(residuals, out / "georef_residuals.csv")

    def targets(t):
        return {k: t.apply(v[None])[0].tolist() for k, v in model_t.items()}

    (out / "georef.json").write_text(json.dumps({
        "tape_horn_tide": sim_shift.as_dict(), "tide_shift_m": dz, "tape_horn_levelled": sim_level.as_dict(),
        "levelled_shift_m": dz_level, "similarity_rtk": sim_rtk.as_dict(), "products": "tape_horn_levelled" if sp_.level_to_water else "tape_horn_tide",
        "targets_tape_horn_tide": targets(sim_shift), "targets_tape_horn_levelled": targets(sim_level),
        "targets_similarity_rtk": targets(sim_rtk), "n_waterline_points": len(model_w)}, indent=1) + "\n")
    # surface and mosaics in the site CRS
    offset = np.round(np.mean([sim.apply(im.C[None])[0] for im in views.images], axis=0))
    offset[2] = 0.0
    wv = _transform_views(views, sim, offset)
    keep = [p for p in rec.points3D.values() if p.track.length() >= sp_.min_track_length]
    pts = sim.apply(np.array([p.xyz for p in keep]))
    tin, grid = tin_dsm(pts, sp_.dsm_cell_m, crs)
    Raster(tin, grid).write(out / "dsm_tin.tif")
    dense_info: dict = {}
    if sp_.dsm_method == "dense":
        from kitegully.dense.surface import dense_surface
        from kitegully.dense.views import ViewSet
        rgb_views = ViewSet([im for im in wv.images if sfm_to_name[im.name].startswith("rgb")], wv.offset, wv.sparse_points)
        d = sp_.dense
        res_d = dense_surface(rgb_views, grid, d["matching"], d["tile_cells"], d["overlap_cells"], d["max_cached_images"])
        Raster(res_d.dsm, grid).write(out / "dsm_dense.tif")
        matched = np.isfinite(res_d.dsm)
        dsm = np.where(matched, res_d.dsm, tin).astype(np.float32)
        dense_info = {"dense_s": res_d.seconds, "dense_matched_share": float(matched[np.isfinite(tin)].mean()),
                      "dense_coverage_seen": res_d.coverage(), "dense_views": len(rgb_views.images)}
        log.info("dense DSM: %.1f %% of the TIN's cells matched in %.0f s", 100 * dense_info["dense_matched_share"], res_d.seconds)
    else:
        dsm = tin
    Raster(dsm, grid).write(out / "dsm.tif")
    slope, aspect = slope_aspect(dsm, grid.cell)
    Raster(slope, grid).write(out / "slope.tif")
    Raster(aspect, grid).write(out / "aspect.tif")
    panels = pd.read_csv(obs / "panel_shots.csv")
    mosaics = {}
    for sensor in ("rgb", "nir"):
        from kitegully.dense.views import ViewSet
        sub = ViewSet([im for im in wv.images if sfm_to_name[im.name].startswith(sensor)], wv.offset, wv.sparse_points)
        if len(sub.images) < 1:
            raise InputError(f"{obs / 'images'}: no {sensor.upper()} photo was registered in the joint SfM model")
        img, og, _ = orthophoto(sub, dsm, grid, upsample=sp_.ortho_upsample, tile_cells=1024, overlap_m=2.0,
                                occlusion_tolerance_m=sp_.occlusion_tolerance_m)
        pan = panels[panels["camera"] == sensor].set_index("channel").loc[["red", "green", "blue"]]
        mosaics[sensor] = white_balance(img, pan["dn_mean"].to_numpy(), float(pan["panel_reflectance"].iloc[0]), sp_.gamma)
    Raster(mosaics["rgb"], og).write(out / "rgb_orthomosaic.tif", band_names=["red", "green", "blue"])
    nir = mosaics["nir"][0]
    Raster(nir, og).write(out / "nir_orthomosaic.tif", band_names=["nir (red channel)"])
    red = mosaics["rgb"][0]
    v = ndvi(nir, red)
    v[~(np.isfinite(nir) & np.isfinite(red))] = np.nan
    Raster(v, og).write(out / "ndvi.tif")
    e = excess_green(*mosaics["rgb"])
    Raster(e, og).write(out / "exg.tif")
    info = {"n_images": summary["n_images"], "n_registered": summary["n_registered"],
            "n_registered_rgb": sum(1 for im in views.images if sfm_to_name[im.name].startswith("rgb")),
            "n_registered_nir": sum(1 for im in views.images if sfm_to_name[im.name].startswith("nir")),
            "n_cameras": n_cams, "n_points3d": summary["n_points3d"], "n_tin_points": int(len(pts)),
            "mean_reprojection_error_px": summary["mean_reprojection_error_px"],
            "targets_triangulated": len(model_t), "sfm_s": t_sfm, "total_s": time.perf_counter() - t0,
            "mosaic_cell_m": og.cell, "dsm_cell_m": grid.cell, "dsm_method": sp_.dsm_method, **dense_info}
    (out / "survey.json").write_text(json.dumps(info, indent=1) + "\n")
    log.info("low-cost survey: %s", info)
    return info


# --------------------------------------------------------------------------- bare soil (OBIA)


@dataclass(frozen=True)
class BareSoilParams:
    """The ``lowcost.bare_soil`` section: the obia stage's kite-scale map on the mosaics.

    Attributes
    ----------
    tile_cells : int
        Tile side of the segmentation (cells) [I] 1024: the 2 cm mosaic of the strip is two tiles.
    min_reflectance : float
        Mosaic cells darker than this in every visible band are no data for both maps [I]
        0.01: no lit natural ground (dark water included, 3-6 %) reflects under 1 % in all
        visible bands, so such cells are unlit or beyond the imaged ground (the twin's
        strip ends in black); their chromatic coordinates, and so ExG, are noise.
    obia : ObiaParams
        The obia stage's method keys (``features`` ... ``classification``, checked by
        :meth:`kitegully.obia.scene.ObiaParams.from_config`); Mayr et al.'s 2 cm settings
        [P 001] suit the 2 cm mosaics. ``classification.index: ndvi`` is this site's choice
        (a NIR band exists); the ExG map of the RGB camera alone is made beside it with
        the same keys.
    """

    tile_cells: int
    obia: Any
    min_reflectance: float

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any]) -> "BareSoilParams":
        """Build from ``lowcost.bare_soil`` (``obia`` checked by ``ObiaParams``); raises InputError naming a bad key."""
        from kitegully.obia.scene import ObiaParams
        config_section(cfg, "lowcost.bare_soil", ["tile_cells", "min_reflectance", "obia"])
        p = ObiaParams.from_config(cfg["obia"])
        if int(cfg["tile_cells"]) < 4 * p.seed_bandwidth_cells:
            raise InputError(f"lowcost.bare_soil.tile_cells: must be at least 4 seed band widths "
                             f"({4 * p.seed_bandwidth_cells} cells), got {cfg['tile_cells']!r}")
        if not 0 <= float(cfg["min_reflectance"]) < 1:
            raise InputError(f"lowcost.bare_soil.min_reflectance: must lie in [0, 1), got {cfg['min_reflectance']!r}")
        return cls(int(cfg["tile_cells"]), p, float(cfg["min_reflectance"]))


def map_bare_soil(rgb_path: str | Path, nir_path: str | Path, dsm_path: str | Path, cfg: Mapping[str, Any],
                  out_dir: str | Path) -> pd.DataFrame:
    """Bare-soil maps of the mosaics by the obia stage's kite-scale OBIA, with each index.

    ``bare_soil_ndvi.tif``: the configured parameters with ``index: ndvi`` (segmentation on
    R, G, B, NIR and slope; NDVI of the NIR camera's and the RGB camera's red channels);
    ``bare_soil_exg.tif``: the same parameters on the RGB mosaic alone with ``index: exg``
    (what an RGB-only team maps; no water mask, ExG cannot see water). Thresholds come from
    each index's own histogram (valley, Otsu alongside), never from the truth. Cells darker
    than ``min_reflectance`` in R, G and B are no data in both. Writes
    ``bare_soil_thresholds.csv`` and returns it. Cost: two OBIA runs, O(N log N) in cells.

    Parameters
    ----------
    rgb_path : path
        White-balanced RGB mosaic (3 bands, reflectance).
    nir_path : path
        NIR mosaic on the same grid.
    dsm_path : path
        DSM of the survey.
    cfg : mapping
        The ``lowcost.bare_soil`` section (:class:`BareSoilParams`).
    out_dir : path
        Output folder, created if missing.

    Returns
    -------
    DataFrame
        One row per index (ndvi, exg): thresholds, water, dark and mapped cells, bare share
        and seconds.
    """
    import tempfile

    p = BareSoilParams.from_config(cfg)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    nd = p.obia if p.obia.index == "ndvi" else replace(p.obia, index="ndvi")
    rgb = Raster.read(rgb_path, band=None)
    if rgb.data.ndim != 3 or rgb.data.shape[0] < 3:
        raise InputError(f"{rgb_path}: RGB mosaic needs 3 bands, has shape {rgb.data.shape}")
    dark = np.all(rgb.data < p.min_reflectance, axis=0)
    rows = []
    with tempfile.TemporaryDirectory(dir=out) as tmp:
        masked = Path(tmp) / "rgb_orthomosaic_lit.tif"
        rgb.with_data(np.where(dark[None], np.nan, rgb.data[:3]).astype(np.float32)).write(masked, band_names=["red", "green", "blue"])
        runs = {"ndvi": (nd, nir_path), "exg": (replace(p.obia, index="exg", water_ndvi_below=None), None)}
        for name, (params, nir) in runs.items():
            rows.append(_bare_soil_run(name, masked, dsm_path, out, params, p.tile_cells, nir, int(dark.sum())))
    tab = pd.DataFrame(rows)
    write_table(tab, out / "bare_soil_thresholds.csv")
    return tab


def _bare_soil_run(name: str, rgb_path: Path, dsm_path: str | Path, out: Path, params, tile_cells: int,
                   nir: str | Path | None, dark_cells: int) -> dict:
    """One OBIA map (:func:`map_bare_soil`) and its row of ``bare_soil_thresholds.csv``."""
    from kitegully.obia.kite import bare_soil_map

    t0 = time.perf_counter()
    path = out / f"bare_soil_{name}.tif"
    thr = bare_soil_map(rgb_path, dsm_path, path, params, tile_cells, nir_path=nir)
    cls, _ = read_raster(path)
    mapped = cls != 255
    row = {"index": name, **thr.as_dict(), "water_cells": thr.water_cells or 0, "dark_cells": dark_cells,
           "mapped_cells": int(mapped.sum()), "bare_share": float(np.mean(cls[mapped] == 1)) if mapped.any() else np.nan,
           "seconds": time.perf_counter() - t0}
    log.info("bare soil by %s: valley %s, Otsu %s, bare share %.3f", name, thr.valley, thr.otsu, row["bare_share"])
    return row


# --------------------------------------------------------------------------- evaluation (twin truth)


def _sim(d: Mapping[str, Any]):
    from kitegully.georef.similarity import Similarity
    return Similarity(float(d["scale"]), np.array(d["rotation"]), np.array(d["translation_m"]))


def _classes_under_mosaic(truth: Raster, grid: GridSpec, dsm: Raster, sim_est, sim_ref) -> np.ndarray:
    """Truth class of the ground each mosaic cell shows, as an operator picking patches in
    the mosaic sees it: the cell (with its DSM height) goes back to the model frame through
    the survey's georeferencing and out to the ground through the RTK-grade block
    (evaluation only), so a georeferencing error of the low-cost block does not mix classes."""
    xs, ys = np.meshgrid(*grid.cell_centres())
    r, c = dsm.grid.index(xs, ys)
    ok = (r >= 0) & (c >= 0) & (r < dsm.grid.height) & (c < dsm.grid.width)
    z = np.full(xs.shape, np.nan)
    z[ok] = dsm.data[r[ok], c[ok]]
    P = np.column_stack([xs.ravel(), ys.ravel(), z.ravel()])
    model = (P - sim_est.t) @ sim_est.R / sim_est.scale
    W = sim_ref.apply(model)
    tr, tc = truth.grid.index(W[:, 0], W[:, 1])
    fin = np.isfinite(W[:, 0]) & np.isfinite(W[:, 1])
    tr, tc = np.where(fin, tr, -1), np.where(fin, tc, -1)
    inside = (tr >= 0) & (tc >= 0) & (tr < truth.grid.height) & (tc < truth.grid.width)
    out = np.zeros(len(P), np.uint8)
    out[inside] = truth.data[tr[inside], tc[inside]]
    return out.reshape(xs.shape)


def _otsu(values: np.ndarray) -> float:
    from skimage.filters import threshold_otsu
    return float(threshold_otsu(values[np.isfinite(values)]))


def _accuracy(pred: np.ndarray, true: np.ndarray) -> dict:
    tp, tn = np.sum(pred & true), np.sum(~pred & ~true)
    fp, fn = np.sum(pred & ~true), np.sum(~pred & true)
    n = tp + tn + fp + fn
    po = (tp + tn) / n
    pe = ((tp + fp) * (tp + fn) + (tn + fn) * (tn + fp)) / n**2
    return {"overall_accuracy": po, "kappa": (po - pe) / (1 - pe), "bare_producers_accuracy": tp / max(tp + fn, 1),
            "bare_users_accuracy": tp / max(tp + fp, 1)}


def score_bare_soil_maps(survey_dir: str | Path, cls: np.ndarray, grid: GridSpec,
                         bare_classes: Collection[str]) -> pd.DataFrame:
    """Accuracy of the OBIA bare-soil maps (``bare_soil_ndvi.tif``, ``bare_soil_exg.tif``)
    against the land cover ``cls`` under the mosaic cells (truth class codes).

    Scored cells: land (not water, as an analyst masks the sea) mapped by both maps, so the
    two indices are compared on the same cells; reference "bare" = ``bare_classes``.
    Per map: overall accuracy, kappa, bare producer's and user's accuracy, the land cells
    the map left unmapped (NDVI: masked as water), and the share of each cover class
    mapped bare. O(cells).

    Parameters
    ----------
    survey_dir : path
        Folder holding ``bare_soil_ndvi.tif`` and ``bare_soil_exg.tif``.
    cls : ndarray (H, W) uint8
        Truth class code under each mosaic cell.
    grid : GridSpec
        Mosaic grid; both maps must lie on it.
    bare_classes : iterable of str
        Cover classes that count as bare.

    Returns
    -------
    DataFrame
        One row per map (ndvi, exg): accuracies, kappa, scored and unmapped land cells and
        the percentage of each class mapped bare.
    """
    from kitegully.lowcost.twin_site import CLASS_CODES
    sv = Path(survey_dir)
    maps = {}
    for name in ("ndvi", "exg"):
        data, g = read_raster(sv / f"bare_soil_{name}.tif")
        if data.shape != cls.shape or g.transform != grid.transform:
            raise InputError(f"{sv / f'bare_soil_{name}.tif'}: not on the mosaic grid {grid}")
        maps[name] = data
    unknown = sorted(set(bare_classes) - set(CLASS_CODES))
    if unknown:
        raise InputError(f"lowcost.evaluation.bare_classes: unknown cover classes {unknown} (known: {list(CLASS_CODES)})")
    land = (cls > 0) & (cls != CLASS_CODES["water"])
    both = land & (maps["ndvi"] != 255) & (maps["exg"] != 255)
    bare_true = np.isin(cls, [CLASS_CODES[c] for c in bare_classes])
    rows = []
    for name, m in maps.items():
        row = {"index": name, **_accuracy(m[both] == 1, bare_true[both]), "cells": int(both.sum()),
               "land_cells_unmapped": int(np.sum(land & (m == 255)))}
        for cname, code in CLASS_CODES.items():
            on = (cls == code) & (m != 255)
            row[f"{cname}_mapped_bare_pct"] = 100.0 * float(np.mean(m[on] == 1)) if on.any() else np.nan
        rows.append(row)
    return pd.DataFrame(rows)


def evaluate_lowcost(survey_dir: str | Path, truth_dir: str | Path, cfg: Mapping[str, Any], seed: int,
                     out_dir: str | Path) -> dict:
    """Score the survey's products against the twin's truth.

    Writes ``ndvi_by_class.csv`` (+ ``.png``: mean ± SD of 15 x 15 px patch means per class
    against the class NDVI the cameras see and the narrow-band NDVI), ``bare_ground_indicators.csv``
    (ExG and NDVI thresholded by Otsu, accuracy against the land cover; water left out by the
    observed NDVI < 0), ``bare_soil_obia.csv`` (the OBIA maps by NDVI and ExG),
    ``georef_truth.csv`` (target and DSM errors) and ``dsm_truth.csv`` (each DSM written:
    products, TIN, dense). O(mosaic cells).

    Parameters
    ----------
    survey_dir : path
        Output folder of :func:`survey_lowcost` with the bare-soil maps of :func:`map_bare_soil`.
    truth_dir : path
        The twin's truth: ``classes.tif``, ``classes.csv``, ``targets.csv``, ``dsm.tif``.
    cfg : mapping
        The ``lowcost.evaluation`` section: ``patch_px``, ``patches_per_class``, ``bare_classes``.
    seed : int
        The run's seed (patch stream ``rng_for(seed, "lowcost", "patches")``).
    out_dir : path
        Output folder, created if missing.

    Returns
    -------
    dict
        Largest absolute NDVI error, median and NMAD of the product DSM's error (m) and
        overall accuracy of each OBIA map; also written to ``evaluation.json``.
    """
    config_section(cfg, "lowcost.evaluation", ["patch_px", "patches_per_class", "bare_classes"])
    from kitegully.lowcost.twin_site import CLASS_CODES
    sv, tr, out = Path(survey_dir), Path(truth_dir), Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    nd = Raster.read(sv / "ndvi.tif")
    truth_cls = Raster.read(tr / "classes.tif")
    classes = pd.read_csv(tr / "classes.csv")
    gj = json.loads((sv / "georef.json").read_text())
    cls = _classes_under_mosaic(truth_cls, nd.grid, Raster.read(sv / "dsm.tif"), _sim(gj[gj["products"]]),
                                _sim(gj["similarity_rtk"]))
    k = int(cfg["patch_px"])
    rng = rng_for(seed, "lowcost", "patches")
    rows = []
    for name, code in CLASS_CODES.items():
        inside = (cls == code) & np.isfinite(nd.data)
        # windows fully inside the class: erode by the half patch
        from scipy import ndimage
        core = ndimage.binary_erosion(inside, np.ones((k, k), bool))
        rr, cc = np.nonzero(core)
        if len(rr) == 0:
            continue
        pick = rng.choice(len(rr), size=min(int(cfg["patches_per_class"]), len(rr)), replace=False)
        means = [float(np.mean(nd.data[r - k // 2:r + k // 2 + 1, c - k // 2:c + k // 2 + 1])) for r, c in zip(rr[pick], cc[pick])]
        t = classes.set_index("class").loc[name]
        rows.append({"class": name, "patches": len(means), "ndvi_mean": float(np.mean(means)), "ndvi_sd": float(np.std(means)),
                     "true_ndvi_camera": float(t["ndvi_camera"]), "true_ndvi_band": float(t["ndvi_band"]),
                     "error": float(np.mean(means) - t["ndvi_camera"])})
    tab = pd.DataFrame(rows)
    write_table(tab, out / "ndvi_by_class.csv")
    from kitegully.io.figures import new_figure, save_figure
    fig, ax = new_figure(figsize=(6, 4))
    x = np.arange(len(tab))
    ax.errorbar(x, tab["ndvi_mean"], yerr=tab["ndvi_sd"], fmt="o", capsize=4, label="mosaic patches (mean ± SD)")
    ax.plot(x, tab["true_ndvi_camera"], "kx", ms=9, label="truth as the cameras see it")
    ax.plot(x, tab["true_ndvi_band"], "r+", ms=9, label="truth, narrow bands (R 660, NIR 740 nm)")
    ax.axhline(0, color="0.6", lw=0.8)
    ax.set_xticks(x, tab["class"])
    ax.set_xlabel("cover class")
    ax.set_ylabel("NDVI (-)")
    ax.legend(fontsize=7)
    save_figure(fig, out / "ndvi_by_class.png")
    # bare-ground indicators
    exg = Raster.read(sv / "exg.tif").data
    land = np.isfinite(nd.data) & np.isfinite(exg) & (nd.data >= 0)          # observed water mask
    scored = land & (cls > 0) & (cls != CLASS_CODES["water"])
    bare_true = np.isin(cls, [CLASS_CODES[c] for c in cfg["bare_classes"]])
    ind = []
    for name, values in (("NDVI", nd.data), ("ExG", exg)):
        t = _otsu(values[land])
        pred = values < t
        ind.append({"indicator": name, "otsu_threshold": t, **_accuracy(pred[scored], bare_true[scored]),
                    "cells": int(scored.sum())})
    write_table(pd.DataFrame(ind), out / "bare_ground_indicators.csv")
    obia = score_bare_soil_maps(sv, cls, nd.grid, cfg["bare_classes"])
    write_table(obia, out / "bare_soil_obia.csv")
    # georeferencing against the truth
    tt = read_points(tr / "targets.csv", "true targets")
    grow = []
    for method, key in (("tape_horn_gps + tide shift (paper)", "targets_tape_horn_tide"),
                        ("tape_horn_gps + waterline levelled + tide", "targets_tape_horn_levelled"),
                        ("similarity_rtk", "targets_similarity_rtk")):
        d = np.array([np.array(gj[key][n]) - tt[n] for n in gj[key] if n in tt])
        grow.append({"method": method, "targets": len(d), "mean_3d_error_m": float(np.linalg.norm(d, axis=1).mean()),
                     "mean_horizontal_error_m": float(np.linalg.norm(d[:, :2], axis=1).mean()),
                     "mean_vertical_error_m": float(d[:, 2].mean())})
    tdsm = Raster.read(tr / "dsm.tif")
    sim_est, sim_ref = _sim(gj[gj["products"]]), _sim(gj["similarity_rtk"])
    drows = []
    for label, name in (("products (dsm.tif)", "dsm.tif"), ("TIN of the tie points", "dsm_tin.tif"),
                        ("dense matching, matched cells only", "dsm_dense.tif")):
        if name != "dsm.tif" and not (sv / name).exists():
            continue
        dsm = Raster.read(sv / name)
        xs, ys = np.meshgrid(*dsm.grid.cell_centres())
        r, c = tdsm.grid.index(xs, ys)
        inside = (r >= 0) & (c >= 0) & (r < tdsm.grid.height) & (c < tdsm.grid.width)
        ok = inside & np.isfinite(dsm.data)
        diff = dsm.data[ok] - tdsm.data[r[ok], c[ok]]
        m = float(np.median(diff))
        # the surface's shape alone: its points taken back to the model and out through the
        # RTK-grade block, so the low-cost block's georeferencing error does not enter
        P = np.column_stack([xs[ok], ys[ok], dsm.data[ok]])
        W = sim_ref.apply((P - sim_est.t) @ sim_est.R / sim_est.scale)
        rr, cc = tdsm.grid.index(W[:, 0], W[:, 1])
        k = (rr >= 0) & (cc >= 0) & (rr < tdsm.grid.height) & (cc < tdsm.grid.width)
        dr = W[k, 2] - tdsm.data[rr[k], cc[k]]
        mr = float(np.median(dr))
        drows.append({"dsm": label, "file": name, "cells": int(ok.sum()), "share_of_cells": float(ok.sum() / max(inside.sum(), 1)),
                      "median_error_m": m, "nmad_m": nmad(diff),
                      "rmse_m": float(np.sqrt(np.mean(diff**2))), "p95_abs_error_m": float(np.percentile(np.abs(diff), 95)),
                      "rtk_frame_median_error_m": mr, "rtk_frame_nmad_m": nmad(dr),
                      "rtk_frame_p95_abs_error_m": float(np.percentile(np.abs(dr - mr), 95))})
        if name == "dsm.tif":
            grow.append({"method": f"DSM ({gj['products']}) - true surface", "targets": int(ok.sum()),
                         "mean_3d_error_m": float(np.sqrt(np.mean(diff**2))), "mean_horizontal_error_m": np.nan,
                         "mean_vertical_error_m": m})
    write_table(pd.DataFrame(drows), out / "dsm_truth.csv")
    med, nmad = drows[0]["median_error_m"], drows[0]["nmad_m"]
    write_table(pd.DataFrame(grow), out / "georef_truth.csv")
    res = {"max_abs_ndvi_error": float(tab["error"].abs().max()), "dsm_median_error_m": med, "dsm_nmad_m": nmad,
           "bare_soil_obia_overall_accuracy": dict(zip(obia["index"], obia["overall_accuracy"].astype(float)))}
    (out / "evaluation.json").write_text(json.dumps(res, indent=1) + "\n")
    return res


# --------------------------------------------------------------------------- RTK comparison block


def adjust_rtk_bundle(observed_dir: str | Path, sfm_dir: str | Path, georef_cfg: Mapping[str, Any], crs: str, seed: int,
                      out_dir: str | Path) -> dict:
    """The comparison block of issue 18: the same joint model georeferenced by the georef
    stage's GCP bundle adjustment with RTK-grade target coordinates (``targets_rtk.csv``)
    and the target clicks, written as an OpenDroneMap ``gcp_list.txt`` first.

    Returns the georef stage's summary; its products go to ``out_dir`` (model, transform,
    ``gcp_residuals.csv``, ``loo_checkpoints.csv``, ``summary.json``...). Cost: the georef
    stage's bundle adjustment, seconds for 56 photos.

    Parameters
    ----------
    observed_dir : path
        Folder holding ``image_clicks.csv`` and ``targets_rtk.csv``.
    sfm_dir : path
        SfM folder of :func:`survey_lowcost` (``model``, ``image_info.json``).
    georef_cfg : mapping
        The georef stage's section (:class:`kitegully.georef.stage.GeorefParams`).
    crs : str
        Site CRS.
    seed : int
        Seed of the georef stage's tie-point choice.
    out_dir : path
        Output folder, created if missing.

    Returns
    -------
    dict
        The georef stage's summary.
    """
    from kitegully.georef.stage import GeorefParams, georeference
    from kitegully.twin.flight_gcps import write_odm_gcp_list

    obs, sfm, out = Path(observed_dir), Path(sfm_dir), Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    clicks = pd.read_csv(obs / "image_clicks.csv")
    t = clicks[clicks["kind"] == "target"].rename(columns={"point": "gcp_id", "u_px": "im_x_px", "v_px": "im_y_px"})
    rtk = pd.read_csv(obs / "targets_rtk.csv").rename(columns={"target": "gcp_id", "x_m": "x", "y_m": "y", "z_m": "z"})
    gcp_file = out / "gcp_list.txt"
    write_odm_gcp_list(gcp_file, crs, t, rtk)
    names = {"model": "model", "transform": "transform.json", "summary": "summary.json", "residuals": "gcp_residuals.csv",
             "loo": "loo_checkpoints.csv", "calibration": "camera_calibration.csv", "cameras": "camera_positions.gpkg",
             "cloud": "sparse_cloud.laz", "figure": "gcp_residuals.png"}
    return georeference(sfm / "model", sfm / "image_info.json", gcp_file, "stored", GeorefParams.from_config(georef_cfg),
                        crs, seed, {k: out / v for k, v in names.items()})
