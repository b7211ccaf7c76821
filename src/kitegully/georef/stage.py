"""The georeferencing stage: its parameters and its entry point :func:`georeference`.

:func:`georeference` reads the GCP file and the SfM model, runs
:func:`kitegully.georef.control.georeference_block` (QA, GCP bundle, leave-one-out) and
writes the products; :class:`GeorefParams` holds the ``georef`` config section.
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import pandas as pd
import pycolmap

from kitegully import InputError
from kitegully.config import checked_choice, checked_number, config_section
from kitegully.georef import export
from kitegully.georef.bundle import Block, BundleSettings
from kitegully.georef.control import georeference_block
from kitegully.georef.gcp_io import read_gcps, read_tape_distances
from kitegully.georef.model import block_from_reconstruction
from kitegully.io.tables import write_table
from kitegully.io.vectors import write_vector
from kitegully.sfm.stage import load_image_infos

log = logging.getLogger(__name__)

GCP_FORMATS = ("auto", "odm", "csv")
PIXEL_FRAMES = ("stored", "display")
METHODS = ("gcp_bundle", "similarity", "tape_horn")
INTRINSICS = ("f", "cx", "cy", "k1", "k2")
LOSSES = ("huber", "linear")


def _choice(value: Any, allowed: tuple, where: str) -> Any:
    if value not in allowed:
        raise InputError(f"{where}: must be one of {', '.join(map(str, allowed))}, got {value!r}")
    return value



@dataclass(frozen=True)
class GeorefQA:
    """Quality checks of the georeferencing (``georef.qa``).

    Attributes
    ----------
    max_triangulation_px : float
        A GCP whose rays miss by more than this RMS reprojection error (px, SfM image
        scale) is not used ([I] about 4 SD of the GCP clicking noise).
    max_residual_m : float
        A GCP off by more than this after the similarity, while the others agree without
        it, is an outlier (m; [I] about 10 SD of the GCP survey).
    coords_tolerance_m : float
        Rows of one GCP whose coordinates differ by more than this are flagged (m).
    min_gcps_trusted : int
        Fewest usable GCPs for the result to be called trustworthy (at least 3).
    required_accuracy_m : float
        Leave-one-out 3-D RMSE the study needs for the result to be called trustworthy
        (m; [I] 2 x the median GSD).
    """

    max_triangulation_px: float
    max_residual_m: float
    coords_tolerance_m: float
    min_gcps_trusted: int
    required_accuracy_m: float

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any]) -> "GeorefQA":
        """Build from ``georef.qa`` (keys of the same names); raises InputError naming a bad key."""
        config_section(cfg, "georef.qa", cls.__dataclass_fields__)
        n = int(cfg["min_gcps_trusted"])
        if n < 3:
            raise InputError(f"georef.qa.min_gcps_trusted: must be at least 3, got {n}")
        return cls(
            max_triangulation_px=float(checked_number(cfg, "max_triangulation_px", "georef.qa")),
            max_residual_m=float(checked_number(cfg, "max_residual_m", "georef.qa")),
            coords_tolerance_m=float(checked_number(cfg, "coords_tolerance_m", "georef.qa", strict=False)),
            min_gcps_trusted=n,
            required_accuracy_m=float(checked_number(cfg, "required_accuracy_m", "georef.qa")),
        )


def bundle_settings_from_config(cfg: Mapping[str, Any], sigma_gcp_xy_m: float, sigma_gcp_z_m: float) -> BundleSettings:
    """:class:`BundleSettings` from ``georef.bundle`` and the GCP survey SDs.

    Keys: ``sigma_tie_px``, ``sigma_gcp_px`` (image measurement SDs, px at SfM scale),
    ``refine_intrinsics`` (subset of f, cx, cy, k1, k2), ``loss`` (huber, linear),
    ``loss_scale`` (Huber threshold, SD units), ``max_iterations``, ``rel_tolerance``.

    Parameters
    ----------
    cfg : mapping
        The ``georef.bundle`` config section.
    sigma_gcp_xy_m, sigma_gcp_z_m : float
        Survey SD of the GCPs in plan and in height (m).

    Returns
    -------
    BundleSettings
        The checked settings.
    """
    config_section(cfg, "georef.bundle", ("sigma_tie_px", "sigma_gcp_px", "refine_intrinsics", "loss", "loss_scale",
                                          "max_iterations", "rel_tolerance"))
    refine = tuple(cfg["refine_intrinsics"])
    for name in refine:
        _choice(name, INTRINSICS, "georef.bundle.refine_intrinsics")
    if int(cfg["max_iterations"]) < 1:
        raise InputError(f"georef.bundle.max_iterations: must be at least 1, got {cfg['max_iterations']!r}")
    return BundleSettings(
        sigma_tie_px=float(checked_number(cfg, "sigma_tie_px", "georef.bundle")),
        sigma_gcp_px=float(checked_number(cfg, "sigma_gcp_px", "georef.bundle")),
        sigma_gcp_xy_m=sigma_gcp_xy_m, sigma_gcp_z_m=sigma_gcp_z_m, refine=refine,
        loss=checked_choice(cfg, "loss", "georef.bundle", LOSSES),
        loss_scale=float(checked_number(cfg, "loss_scale", "georef.bundle")),
        max_iterations=int(cfg["max_iterations"]),
        rel_tolerance=float(checked_number(cfg, "rel_tolerance", "georef.bundle")),
    )


@dataclass(frozen=True)
class GeorefParams:
    """Parameters of the georeferencing stage (the ``georef`` config section).

    Attributes
    ----------
    gcp_format : str
        ``auto`` (CSV for a .csv suffix, else OpenDroneMap ``gcp_list.txt``), ``odm`` or ``csv``.
    csv_crs : str or None
        CRS of a CSV GCP file's coordinates; None = the site CRS.
    gcp_pixel_frame : str
        Frame of the file's pixel coordinates: ``stored`` (as stored in the image file,
        ODM's convention) or ``display`` (after the EXIF rotation).
    gcp_pixel_scale : float
        File pixels per full-resolution pixel (1 when measured on the original images).
    gcp_pixel_offset_px : float
        Added to the file's pixel coordinates: 0.5 when the file puts pixel centres at
        integer coordinates, 0 when the image corner is at 0 (COLMAP's convention).
    method : str
        ``gcp_bundle`` (similarity, then bundle adjustment with GCP terms), ``similarity``
        (7-parameter transform only) or ``tape_horn`` (scale from taped distances plus
        Horn's method on low-accuracy GPS positions [P, paper 004]).
    tape_file : str or None
        CSV ``gcp_a,gcp_b,distance_m`` of taped distances; required by ``tape_horn``.
    sigma_gcp_xy_m, sigma_gcp_z_m : float
        SD of the surveyed GCP positions per horizontal axis and in height (m; [P] RTK
        ±1.5 cm on the twin).
    max_tie_points : int
        Most tie points in the GCP bundle adjustment; 0 = all ([I] a budget that keeps the
        adjustment's cost bounded while the intrinsics stay determined).
    tie_grid : tuple of int or None
        ``(columns, rows)`` grid cut into every image for a balanced tie-point choice; None =
        longest tracks of the whole block first.
    qa : GeorefQA
        Quality checks (``georef.qa``).
    bundle : BundleSettings
        Weights and options of the GCP bundle adjustment (``georef.bundle`` with the two
        survey SDs above).
    arrow_scale : float or None
        Map metres per metre of residual for the residual figure's arrows
        (``georef.figure.arrow_scale``); None = automatic.
    cloud_format : str
        File format of the sparse cloud: ``laz`` (LAS 1.4 compressed with LASzip, laspy's
        ``lazrs`` backend; opens in QGIS, CloudCompare, PDAL) or ``las`` (the same points
        uncompressed). The rule names the output ``sparse_cloud.<cloud_format>``.
    camera_from_first_epoch : bool
        Later survey epochs of a site (issue 17) take the camera's intrinsics as the first
        epoch's GCP adjustment found them and keep them fixed (optional key; default
        false). [I] Same camera body and lens, focused at infinity: a weaker later block
        (fewer photos, strips and clicks) cannot separate focal length from flying height
        (dz = H·Δf/f) and bends into a dome with a wrong f and k1 (James & Robson 2014);
        the first epoch's stronger block calibrates it better. No effect on the first epoch.
    """

    gcp_format: str
    csv_crs: str | None
    gcp_pixel_frame: str
    gcp_pixel_scale: float
    gcp_pixel_offset_px: float
    method: str
    tape_file: str | None
    sigma_gcp_xy_m: float
    sigma_gcp_z_m: float
    max_tie_points: int
    tie_grid: tuple[int, int] | None
    qa: GeorefQA
    bundle: BundleSettings
    arrow_scale: float | None
    cloud_format: str
    camera_from_first_epoch: bool = False

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any]) -> "GeorefParams":
        """Build from the ``georef`` config section; raises InputError naming a bad key."""
        config_section(cfg, "georef", ("gcp_format", "csv_crs", "gcp_pixel_frame", "gcp_pixel_scale",
                                       "gcp_pixel_offset_px", "method", "tape_file", "sigma_gcp_xy_m", "sigma_gcp_z_m",
                                       "max_tie_points", "tie_grid", "qa", "bundle", "figure", "cloud_format"),
                       optional=("camera_from_first_epoch",))
        method = checked_choice(cfg, "method", "georef", METHODS)
        if method == "tape_horn" and not cfg["tape_file"]:
            raise InputError("georef.tape_file: the tape_horn method needs a file of taped distances")
        grid = cfg["tie_grid"]
        if grid is not None and (len(grid) != 2 or min(int(v) for v in grid) < 1):
            raise InputError(f"georef.tie_grid: must be [columns, rows] of at least 1, got {grid!r}")
        if int(cfg["max_tie_points"]) < 0:
            raise InputError(f"georef.max_tie_points: must be at least 0, got {cfg['max_tie_points']!r}")
        fig = config_section(cfg["figure"], "georef.figure", ("arrow_scale",))
        sxy = float(checked_number(cfg, "sigma_gcp_xy_m", "georef"))
        sz = float(checked_number(cfg, "sigma_gcp_z_m", "georef"))
        return cls(
            gcp_format=checked_choice(cfg, "gcp_format", "georef", GCP_FORMATS),
            csv_crs=cfg["csv_crs"],
            gcp_pixel_frame=checked_choice(cfg, "gcp_pixel_frame", "georef", PIXEL_FRAMES),
            gcp_pixel_scale=float(checked_number(cfg, "gcp_pixel_scale", "georef")),
            gcp_pixel_offset_px=float(cfg["gcp_pixel_offset_px"]),
            method=method,
            tape_file=cfg["tape_file"] or None,
            sigma_gcp_xy_m=sxy,
            sigma_gcp_z_m=sz,
            max_tie_points=int(cfg["max_tie_points"]),
            tie_grid=tuple(int(v) for v in grid) if grid else None,
            qa=GeorefQA.from_config(cfg["qa"]),
            bundle=bundle_settings_from_config(cfg["bundle"], sxy, sz),
            arrow_scale=None if fig["arrow_scale"] is None else float(fig["arrow_scale"]),
            cloud_format=checked_choice(cfg, "cloud_format", "georef", ("laz", "las")),
            camera_from_first_epoch=bool(cfg.get("camera_from_first_epoch", False)),
        )


def georeference(
    model_dir: str | Path, image_info_json: str | Path, gcp_file: str | Path, sfm_frame: str, params: GeorefParams,
    crs: str, seed: int, out: Mapping[str, str | Path], attribution: str | None = None, gcp_source: str | None = None,
    camera_calibration: str | Path | None = None,
) -> dict:
    """Georeference the SfM model with the GCPs and write the stage's products.

    Parameters
    ----------
    model_dir : path
        The SfM stage's COLMAP model folder.
    image_info_json : path
        The SfM stage's ``image_info.json``.
    gcp_file : path
        GCP file (ODM ``gcp_list.txt`` or CSV, as ``params.gcp_format`` says).
    sfm_frame : str
        Pixel frame of the SfM (``sfm.image_frame``).
    params : GeorefParams
        The stage's parameters.
    crs : str
        Site CRS.
    seed : int
        Seed of the tie-point choice.
    out : mapping
        Product name → path; keys model, transform, summary, residuals, loo, calibration,
        cameras, cloud, figure.
    attribution : str, optional
        Data attribution printed on the figure.
    gcp_source : str, optional
        The GCP file as the user gave it (``gcp_file`` may be its checked copy), named in
        error messages.
    camera_calibration : path, optional
        Another epoch's ``camera_calibration.csv``: its adjusted intrinsics replace the
        SfM ones and stay fixed in the adjustment (``params.camera_from_first_epoch``).

    Returns
    -------
    dict
        The summary written to ``out["summary"]``.

    Raises
    ------
    InputError
        Unreadable model or image information, bad GCP or tape file, fewer than three usable GCPs.
    """
    infos = load_image_infos(image_info_json)
    try:
        rec = pycolmap.Reconstruction(str(model_dir))
    except Exception as exc:  # pycolmap raises RuntimeError/ValueError on a bad folder
        raise InputError(f"{model_dir}: cannot read the COLMAP model ({exc})") from None
    gcps = read_gcps(gcp_file, crs, params.gcp_format, params.csv_crs)
    log.info("read %d GCPs with %d observations from %s", len(gcps), sum(len(g.images) for g in gcps), gcp_file)
    tape = None
    if params.method == "tape_horn":
        df = read_tape_distances(params.tape_file)
        tape = list(zip(df["gcp_a"], df["gcp_b"], df["distance_m"]))
    block, index = block_from_reconstruction(
        rec, params.max_tie_points, seed, params.tie_grid,
    )
    rows = {name.split("/")[-1]: k for k, name in enumerate(index.image_names)}
    sfm_block = block
    if camera_calibration is not None:
        block = with_calibration(block, camera_calibration)
        params = replace(params, bundle=replace(params.bundle, refine=()))
    res = georeference_block(block, gcps, infos, rows, params, sfm_frame, tape, str(gcp_source or gcp_file))

    rec = export.write_model(rec, res.block, index, out["model"])
    export.write_transform(out["transform"], crs, res.offset, res.transform.as_dict(), res.report)
    export.write_residual_tables(res.residuals, res.loo, out["residuals"], out["loo"])
    write_table(export.calibration_table(sfm_block, res.block, index, rec), out["calibration"])
    cams = export.camera_positions(res.block, index, res.offset, crs, {i.sfm_name: i.name for i in infos})
    write_vector(cams, out["cameras"])
    n_pts = export.write_las(rec, res.offset, crs, out["cloud"])
    survey = {g.gcp_id: g.xyz for g in gcps}
    export.residual_figure(res.residuals, res.loo, survey, cams, out["figure"], params.arrow_scale, attribution)
    summary = dict(res.report)
    summary.update(n_points_cloud=n_pts, crs=crs, gcp_file=str(gcp_file))
    Path(out["summary"]).write_text(json.dumps(export.clean_json(summary), indent=2) + "\n", encoding="utf-8")
    verdict = "CAN" if summary["trusted"] else "can NOT"
    log.info("georeferencing %s be trusted: %s", verdict, "; ".join(summary["trust_reasons"]) or "all checks passed")
    log.info("diagnosis: %s (%s)", summary["diagnosis"], summary["diagnosis_text"])
    return summary


def with_calibration(block: Block, calibration_csv: str | Path) -> Block:
    """``block`` with the adjusted intrinsics of another epoch's ``camera_calibration.csv``.

    One row per camera, in the same order and of the same image size; raises InputError
    naming the file otherwise.
    """
    try:
        cal = pd.read_csv(calibration_csv)
    except (OSError, ValueError) as exc:
        raise InputError(f"{calibration_csv}: cannot read the camera calibration ({exc})") from None
    cols = ["f_px_adjusted", "cx_px_adjusted", "cy_px_adjusted", "k1_adjusted", "k2_adjusted"]
    if not set(cols) <= set(cal.columns) or len(cal) != len(block.intr):
        raise InputError(f"{calibration_csv}: needs one row per camera ({len(block.intr)}) with the columns {', '.join(cols)}")
    out = block.copy()
    out.intr = cal[cols].to_numpy(float)
    log.info("camera intrinsics fixed at %s: %s (SfM had %s)", calibration_csv, np.round(out.intr, 5).tolist(),
             np.round(block.intr, 5).tolist())
    return out
