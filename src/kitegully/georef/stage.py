"""The georeferencing stage end to end: read GCPs and the SfM model, adjust, write products."""

from __future__ import annotations

import json
import logging
from pathlib import Path

import pycolmap

from kitegully import InputError
from kitegully.georef import export
from kitegully.georef.gcp_io import read_gcps, read_tape_distances
from kitegully.georef.model import block_from_reconstruction
from kitegully.georef.pipeline import georeference
from kitegully.io.tables import write_table
from kitegully.io.vectors import write_vector
from kitegully.sfm.stage import load_image_infos

log = logging.getLogger(__name__)


def run_georef_stage(
    model_dir: str | Path, image_info_json: str | Path, gcp_file: str | Path, sfm_frame: str, params: dict, crs: str,
    seed: int, out: dict, attribution: str | None = None,
) -> dict:
    """Georeference the SfM model; ``out`` maps product names to paths.

    Keys of ``out``: model, transform, summary, residuals, loo, calibration, cameras, cloud, figure.
    """
    infos = load_image_infos(image_info_json)
    try:
        rec = pycolmap.Reconstruction(str(model_dir))
    except Exception as exc:  # pycolmap raises RuntimeError/ValueError on a bad folder
        raise InputError(f"{model_dir}: cannot read the COLMAP model ({exc})") from None
    gcps = read_gcps(gcp_file, crs, params["gcp_format"], params["csv_crs"])
    log.info("read %d GCPs with %d observations from %s", len(gcps), sum(len(g.images) for g in gcps), gcp_file)
    tape = None
    if params["method"] == "tape_horn":
        if not params["tape_file"]:
            raise InputError("georef.tape_file: the tape_horn method needs a file of taped distances")
        df = read_tape_distances(params["tape_file"])
        tape = list(zip(df["gcp_a"], df["gcp_b"], df["distance_m"]))
    block, index = block_from_reconstruction(
        rec, params["max_tie_points"], seed, tuple(params["tie_grid"]) if params["tie_grid"] else None,
    )
    rows = {name.split("/")[-1]: k for k, name in enumerate(index.image_names)}
    res = georeference(block, gcps, infos, rows, params, sfm_frame, tape)

    rec = export.write_model(rec, res.block, index, res.offset, out["model"])
    export.write_transform(out["transform"], crs, res.offset, res.transform.as_dict(), res.report)
    export.write_residual_tables(res.residuals, res.loo, out["residuals"], out["loo"])
    write_table(export.calibration_table(block, res.block, index, rec), out["calibration"])
    cams = export.camera_positions(res.block, index, res.offset, crs, {i.sfm_name: i.name for i in infos})
    write_vector(cams, out["cameras"])
    n_pts = export.write_las(rec, res.offset, crs, out["cloud"])
    survey = {g.gcp_id: g.xyz for g in gcps}
    export.residual_figure(res.residuals, res.loo, survey, cams, out["figure"], params["figure"]["arrow_scale"], attribution)
    summary = dict(res.report)
    summary.update(n_points_cloud=n_pts, crs=crs, gcp_file=str(gcp_file))
    Path(out["summary"]).write_text(json.dumps(export.clean_json(summary), indent=2) + "\n", encoding="utf-8")
    verdict = "CAN" if summary["trusted"] else "can NOT"
    log.info("georeferencing %s be trusted: %s", verdict, "; ".join(summary["trust_reasons"]) or "all checks passed")
    log.info("diagnosis: %s (%s)", summary["diagnosis"], summary["diagnosis_text"])
    return summary
