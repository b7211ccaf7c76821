"""The ``lowcost`` stage (issue 18, paper 004): the survey's entry points, named after what they make.

- :func:`measure_spectral_response`: camera responses from a simulated ColorChecker shot.
- :func:`survey_lowcost`: joint RGB+NIR SfM, tape/Horn/tide georeferencing, DSM, white-balanced
  RGB and NIR mosaics, NDVI, ExG, slope, aspect (matches by sensor pair: :mod:`.matches`;
  TIN DSM and white balance: :mod:`.products`).

The stage's other entry points are beside the modules they drive: :func:`.bare_soil.map_bare_soil`
(the OBIA maps of the mosaics), :func:`.rtk.adjust_rtk_bundle` (the RTK comparison block) and
:func:`.evaluation.evaluate_lowcost` (against the twin's truth; evaluation only).
"""

from __future__ import annotations

import json
import logging
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import pandas as pd
from PIL import Image

from kitegully import InputError
from kitegully.config import config_section
from kitegully.io.raster import Raster
from kitegully.io.tables import write_table
from kitegully.lowcost import spectral as sp
from kitegully.lowcost.georef import (georeference_rtk, georeference_tape_horn, read_points, read_tape,
                                      triangulate)
from kitegully.lowcost.matches import matches_by_pair_type
from kitegully.lowcost.products import tin_dsm, views_in_site_crs, white_balance
from kitegully.lowcost.surface import slope_aspect
from kitegully.obia.indices import excess_green, ndvi
from kitegully.seeds import rng_for

log = logging.getLogger(__name__)


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
    from kitegully.dense.views import ViewSet, views_from_reconstruction
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
    wv = views_in_site_crs(views, sim, offset)
    keep = [p for p in rec.points3D.values() if p.track.length() >= sp_.min_track_length]
    pts = sim.apply(np.array([p.xyz for p in keep]))
    tin, grid = tin_dsm(pts, sp_.dsm_cell_m, crs)
    Raster(tin, grid).write(out / "dsm_tin.tif")
    dense_info: dict = {}
    if sp_.dsm_method == "dense":
        from kitegully.dense.surface import dense_surface
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
