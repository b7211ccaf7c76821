"""The SfM stage end to end: prepare images, reconstruct, write the model and its summary."""

from __future__ import annotations

import json
import logging
import time
from dataclasses import asdict
from pathlib import Path

from kitegully import InputError
from kitegully.io.tables import write_table
from kitegully.sfm.images import ImageInfo, list_images, prepare_images
from kitegully.sfm.priors import positions_from_log
from kitegully.sfm.reconstruct import run_sfm
from kitegully.sfm.summary import image_table, model_summary

log = logging.getLogger(__name__)


def run_sfm_stage(
    images_dir: str | Path, work_dir: str | Path, model_dir: str | Path, summary_json: str | Path,
    images_csv: str | Path, image_info_json: str | Path, params: dict, seed: int, threads: int,
    camera_log: str | Path | None = None, crs: str | None = None,
) -> dict:
    """Prepare the images, run pycolmap and write ``summary.json`` and the image table.

    ``params`` is the ``sfm`` config section. ``camera_log`` (GPX/CSV of the camera's GPS
    logger, positions in ``crs``) gives approximate positions for spatial matching.
    Returns the summary.
    """
    t0 = time.perf_counter()
    work_dir = Path(work_dir)
    files = list_images(images_dir)
    infos = prepare_images(
        files, work_dir / "images", params["max_image_size"], params["image_frame"], params["skip_unreadable"],
        params["jpeg_quality"],
    )
    t1 = time.perf_counter()
    positions = None
    if camera_log is not None:
        m = params["matching"]
        positions = positions_from_log(infos, camera_log, crs, m["log_time_offset_s"], m["log_max_gap_s"])
    rec, timings = run_sfm(infos, work_dir / "images", work_dir, model_dir, params, seed, threads, positions, images_dir)
    total = time.perf_counter() - t0
    summary = model_summary(rec, infos)
    if summary["images_left_out"]:
        log.warning("images left out of the largest model: %s", ", ".join(summary["images_left_out"]))
    summary.update(
        image_frame=params["image_frame"], max_image_size_px=params["max_image_size"], threads=threads,
        prepare_s=t1 - t0, total_s=total, images_per_minute=len(infos) / total * 60.0, **timings,
    )
    Path(summary_json).write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    write_table(image_table(rec, infos), images_csv)
    Path(image_info_json).write_text(json.dumps([asdict(i) for i in infos], indent=1) + "\n", encoding="utf-8")
    log.info("SfM: %d of %d images registered, %d points, %.3f px mean reprojection error, %.1f images/min",
             summary["n_registered"], summary["n_images"], summary["n_points3d"],
             summary["mean_reprojection_error_px"], summary["images_per_minute"])
    return summary


def load_image_infos(path: str | Path) -> list[ImageInfo]:
    """The ``ImageInfo`` list the SfM stage wrote."""
    try:
        return [ImageInfo(**d) for d in json.loads(Path(path).read_text(encoding="utf-8"))]
    except (OSError, ValueError, TypeError) as exc:
        raise InputError(f"{path}: cannot read the image information of the SfM stage ({exc})") from None
