"""The SfM stage: its parameters and its entry point :func:`reconstruct_model`.

:func:`reconstruct_model` prepares the images, runs pycolmap (features, matching,
incremental, global or hierarchical mapping with one shared self-calibrated camera) and writes the model,
``summary.json``, the image table and ``image_info.json``; :class:`SfmParams` holds the
``sfm`` config section.
"""

from __future__ import annotations

import json
import logging
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Mapping

from kitegully import InputError
from kitegully.config import checked_number, config_section
from kitegully.io.tables import write_table
from kitegully.sfm.images import ImageInfo, list_images, prepare_images
from kitegully.sfm.priors import positions_from_log
from kitegully.sfm.reconstruct import DEFAULT_GLOBAL_BA_GROWTH, MAPPERS, run_sfm
from kitegully.sfm.summary import image_table, model_summary

log = logging.getLogger(__name__)

MATCHING_METHODS = ("auto", "sequential", "exhaustive", "spatial")
#: optional boolean keys of ``sfm``: affine-covariant SIFT and guided matching (default false)
SIFT_OPTIONAL = ("estimate_affine_shape", "domain_size_pooling", "guided_matching")



@dataclass(frozen=True)
class SfmMatching:
    """Image pair selection and the camera GPS log (``sfm.matching``).

    Attributes
    ----------
    method : str
        ``sequential`` (capture order, ``overlap`` neighbours), ``exhaustive`` (all pairs),
        ``spatial`` (nearest images by logged position) or ``auto`` (exhaustive up to
        ``exhaustive_max_images``, else spatial with a camera log, else sequential).
    overlap : int
        Neighbours in capture order matched with each image ([I] consecutive kite photos
        overlap for about this many frames).
    exhaustive_max_images : int
        Largest image count matched exhaustively by ``auto`` ([I] quadratic cost).
    camera_log : str or None
        GPS log of the camera: a path, ``flight`` (a twin's simulated logger; resolved by the
        rule) or None.
    log_time_offset_s : float
        Camera clock minus GPS clock (s).
    log_max_gap_s : float
        Images further than this from any GPS fix get no position (s).
    gps_sigma_m : float
        SD of the logged positions (m), stored with the priors ([P] QSTARZ-class logger).
    spatial_max_distance_m : float
        Spatial matching pairs images whose logged positions are closer than this (m; [I]
        about one image footprint).
    spatial_max_neighbors : int
        At most this many nearest images are matched with each image (spatial).
    """

    method: str
    overlap: int
    exhaustive_max_images: int
    camera_log: str | None
    log_time_offset_s: float
    log_max_gap_s: float
    gps_sigma_m: float
    spatial_max_distance_m: float
    spatial_max_neighbors: int

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any]) -> "SfmMatching":
        """Build from ``sfm.matching`` (keys of the same names); raises InputError naming a bad key."""
        config_section(cfg, "sfm.matching", cls.__dataclass_fields__)
        if cfg["method"] not in MATCHING_METHODS:
            raise InputError(f"sfm.matching.method: must be one of {', '.join(MATCHING_METHODS)}, got {cfg['method']!r}")
        for key, low in (("overlap", 1), ("exhaustive_max_images", 2), ("spatial_max_neighbors", 1)):
            checked_number(cfg, key, "sfm.matching", low, strict=False)
        for key in ("log_max_gap_s", "gps_sigma_m", "spatial_max_distance_m"):
            checked_number(cfg, key, "sfm.matching")
        return cls(**{k: cfg[k] for k in cls.__dataclass_fields__})


@dataclass(frozen=True)
class SfmParams:
    """Parameters of the SfM stage (the ``sfm`` config section).

    Attributes
    ----------
    image_frame : str
        Pixel frame SfM works in: ``stored`` (the sensor's pixels as stored in the file,
        one camera even when some files carry an EXIF rotation tag) or ``display`` (turned
        upright by the EXIF orientation tag, one camera per image shape).
    max_image_size : int
        Longest image side given to SfM (px); 0 keeps the full resolution.
    skip_unreadable : bool
        Skip corrupt or truncated images with a warning instead of stopping.
    jpeg_quality : int
        JPEG quality (50-100) of the prepared copies SfM reads.
    camera_model : str
        COLMAP camera model, ``SIMPLE_RADIAL`` or ``RADIAL`` (f, cx, cy, k1, k2).
    default_focal_factor : float
        Focal length prior as a multiple of the longest image side when EXIF has none.
    max_num_features : int
        Most SIFT features per image.
    first_octave : int
        First SIFT octave: -1 doubles the image first (COLMAP's default, about 4x the cost),
        0 starts at full resolution ([I] enough where the GSD is far below the DEM cell).
    refine_principal_point : bool
        Refine the principal point in COLMAP's bundle adjustment (self-calibration).
    min_num_matches : int
        Fewest verified matches for an image pair to be used by the mapper.
    matching : SfmMatching
        Pair selection and camera log (``sfm.matching``).
    threads : int
        CPU threads of the rule (Snakemake ``threads:``; the script passes the granted count).
    deterministic : bool
        Reruns give the same model bit for bit: features, matching and mapping on one
        thread with every random choice seeded from the config's seed ([I] on for twins,
        whose numbers are compared between runs; ``threads`` is then ignored).
    mapper : str
        How the matched images become one model (optional key, default ``incremental``):
        ``incremental`` (COLMAP: one image at a time, each followed by local and, as the
        model grows, global bundle adjustments), ``global`` (GLOMAP-style: rotation
        averaging and global positioning of all images at once, then a few global bundle
        adjustments) or ``hierarchical`` (overlapping clusters of at most 500 images mapped
        incrementally and merged). All end with a global bundle adjustment refining the
        camera's intrinsics. [I] Incremental fits tens of images (the default twin's 57: 43 s
        of CPU against global's 47 s, same accuracy); its repeated global adjustments over a growing model make its cost grow
        superlinearly with the image count, so global (or hierarchical) fits the hundreds
        of a whole catchment, where the GPS-log spatial matching already gives a dense,
        well-connected view graph for rotation averaging.
    estimate_affine_shape, domain_size_pooling : bool
        Affine-covariant SIFT (optional keys, default false): each keypoint's affine shape is
        estimated and the affine-normalised patch described (``domain_size_pooling``: the
        descriptor pooled over patch sizes). [I] plain SIFT is invariant to similarities
        only; two views of one surface seen at tilts ``t = 1/sin(grazing angle)`` from
        azimuths ``Δφ`` apart differ by the transition tilt τ with
        ``τ + 1/τ = 2 + (t − 1/t)² sin²Δφ``, and SIFT's matches collapse near τ ≈ 2. Kite
        photos look down (t ≈ 1) and need neither; low oblique pole photos of a steep slope
        (close-range scene 08: t ≈ 3.2, limit reached at Δφ ≈ 13°) do. CPU only, several
        times the plain extraction cost.
    guided_matching : bool
        Second, geometry-guided matching of each verified pair (optional, default false).
        [I] recovers matches the ratio test rejects between views of very different tilt.
    global_ba_growth : float
        The incremental mapper adjusts the whole model again each time its registered
        images or points have grown by this factor (optional, default 1.1 = COLMAP's
        ``ba_global_frames_ratio`` and ``ba_global_points_ratio``); local adjustments of
        each new image's neighbours run in between and the final global adjustment is the
        same. [I] The global adjustments over a model that grows to n images cost about
        ``g / (g − 1)`` adjustments of the final model (a geometric series), i.e. 11 at
        g = 1.1 and 4.3 at 1.3: a compute setting for blocks of hundreds of images, where
        those adjustments are most of the mapping time.
    """

    image_frame: str
    max_image_size: int
    skip_unreadable: bool
    jpeg_quality: int
    camera_model: str
    default_focal_factor: float
    max_num_features: int
    first_octave: int
    refine_principal_point: bool
    min_num_matches: int
    matching: SfmMatching
    threads: int
    deterministic: bool
    mapper: str = "incremental"
    estimate_affine_shape: bool = False
    domain_size_pooling: bool = False
    guided_matching: bool = False
    global_ba_growth: float = DEFAULT_GLOBAL_BA_GROWTH

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any]) -> "SfmParams":
        """Build from the ``sfm`` config section; raises InputError naming a bad key."""
        optional = ("mapper", "global_ba_growth") + SIFT_OPTIONAL
        config_section(cfg, "sfm", [k for k in cls.__dataclass_fields__ if k not in optional], optional=optional)
        cfg = {"mapper": "incremental", "global_ba_growth": DEFAULT_GLOBAL_BA_GROWTH,
               **{k: False for k in SIFT_OPTIONAL}, **cfg}
        for key, allowed in (("image_frame", ("stored", "display")), ("camera_model", ("SIMPLE_RADIAL", "RADIAL")),
                             ("mapper", MAPPERS)):
            if cfg[key] not in allowed:
                raise InputError(f"sfm.{key}: must be one of {', '.join(allowed)}, got {cfg[key]!r}")
        for key, low in (("max_image_size", 0), ("max_num_features", 100), ("min_num_matches", 5), ("threads", 1),
                         ("jpeg_quality", 50), ("first_octave", -1)):
            checked_number(cfg, key, "sfm", low, strict=False)
        if cfg["jpeg_quality"] > 100 or cfg["first_octave"] > 2:
            raise InputError("sfm.jpeg_quality must be at most 100 and sfm.first_octave at most 2")
        checked_number(cfg, "default_focal_factor", "sfm")
        checked_number(cfg, "global_ba_growth", "sfm", 1.0)
        for key in ("deterministic",) + SIFT_OPTIONAL:
            if not isinstance(cfg[key], bool):
                raise InputError(f"sfm.{key}: must be true or false, got {cfg[key]!r}")
        values = {k: cfg[k] for k in cls.__dataclass_fields__ if k != "matching"}
        return cls(matching=SfmMatching.from_config(cfg["matching"]), **values)


def reconstruct_model(
    images_dir: str | Path, work_dir: str | Path, model_dir: str | Path, summary_json: str | Path,
    images_csv: str | Path, image_info_json: str | Path, params: SfmParams, seed: int, threads: int,
    camera_log: str | Path | None = None, crs: str | None = None,
) -> dict:
    """Prepare the images, run pycolmap and write the model, ``summary.json`` and the image tables.

    Parameters
    ----------
    images_dir : path
        Folder of the photographs.
    work_dir, model_dir : path
        Work folder (prepared images, database) and the output COLMAP model folder.
    summary_json, images_csv, image_info_json : path
        Outputs: model statistics, per-image table, prepared-image information.
    params : SfmParams
        The stage's parameters.
    seed : int
        pycolmap's random seed.
    threads : int
        Threads granted to the rule.
    camera_log : path, optional
        GPX/CSV of the camera's GPS logger (positions in ``crs``) for spatial matching.
    crs : str, optional
        Site CRS of the camera log positions.

    Returns
    -------
    dict
        The summary written to ``summary_json``.

    Raises
    ------
    InputError
        No readable image, or an unreadable camera log.
    """
    t0 = time.perf_counter()
    work_dir = Path(work_dir)
    files = list_images(images_dir)
    infos = prepare_images(
        files, work_dir / "images", params.max_image_size, params.image_frame, params.skip_unreadable,
        params.jpeg_quality,
    )
    t1 = time.perf_counter()
    positions = None
    if camera_log is not None:
        m = params.matching
        positions = positions_from_log(infos, camera_log, crs, m.log_time_offset_s, m.log_max_gap_s)
    rec, timings = run_sfm(infos, work_dir / "images", work_dir, model_dir, params, seed, threads, positions, images_dir)
    total = time.perf_counter() - t0
    summary = model_summary(rec, infos)
    if summary["images_left_out"]:
        log.warning("images left out of the largest model: %s", ", ".join(summary["images_left_out"]))
    summary.update(
        image_frame=params.image_frame, max_image_size_px=params.max_image_size, threads=threads,
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
