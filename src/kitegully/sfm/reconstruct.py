"""pycolmap wrapper: SIFT features, matching suited to kite sequences, mapping (incremental, global or hierarchical).

The kite camera has one fixed lens, so all images of one shape share one camera whose
focal length, principal point and radial distortion are refined (self-calibration) by
COLMAP's bundle adjustment.
"""

from __future__ import annotations

import logging
import shutil
import time
from collections import defaultdict
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pycolmap

from kitegully import InputError
from kitegully.sfm.feature_cap import cap_features
from kitegully.sfm.images import ImageInfo
from kitegully.sfm.priors import write_position_priors

if TYPE_CHECKING:
    from kitegully.sfm.stage import SfmParams

log = logging.getLogger(__name__)

CAMERA_MODELS = ("SIMPLE_RADIAL", "RADIAL")


def camera_params(model: str, focal_px: float, width: int, height: int) -> str:
    """Starting parameters of a COLMAP camera as its comma-separated string.

    Parameters
    ----------
    model : str
        COLMAP camera model: ``SIMPLE_RADIAL`` or ``RADIAL``.
    focal_px : float
        Focal length prior (px).
    width, height : int
        Image size (px); the principal point starts at the image centre.

    Returns
    -------
    str
        ``f,cx,cy`` followed by one zero radial term (``SIMPLE_RADIAL``) or two (``RADIAL``).

    Raises
    ------
    InputError
        ``model`` is not one of :data:`CAMERA_MODELS`.
    """
    cx, cy = width / 2.0, height / 2.0
    if model == "SIMPLE_RADIAL":
        return f"{focal_px},{cx},{cy},0"
    if model == "RADIAL":
        return f"{focal_px},{cx},{cy},0,0"
    raise InputError(f"sfm.camera_model: '{model}' is not one of {', '.join(CAMERA_MODELS)}")


def extract_features(
    database: Path,
    image_dir: Path,
    infos: list[ImageInfo],
    camera_model: str,
    default_focal_factor: float,
    max_num_features: int,
    num_threads: int,
    first_octave: int = -1,
    estimate_affine_shape: bool = False,
    domain_size_pooling: bool = False,
) -> None:
    """SIFT features for every prepared image; one shared camera per camera group.

    A camera group is one EXIF camera (make and model) at one image shape: a folder with
    photos of two cameras gets two self-calibrated cameras.

    ``first_octave`` -1 doubles the image first (COLMAP's default, most features, about 4x
    the cost); 0 starts at full resolution.

    ``estimate_affine_shape`` fits each keypoint's affine shape (VLFeat's covariant detector)
    and describes the affine-normalised patch, so a surface seen at different tilts still
    matches (plain SIFT is similarity-invariant only: its matches collapse beyond a
    transition tilt of about 2); ``domain_size_pooling`` pools each descriptor over a range
    of patch sizes. Both run on the CPU only (COLMAP's GPU SIFT lacks them) and cost several
    times the plain extraction.

    The focal-length prior is the median EXIF focal length of the group (in SfM pixels),
    or ``default_focal_factor`` × the larger image side when EXIF lacks it.

    Parameters
    ----------
    database : Path
        The COLMAP database the features and cameras are written to.
    image_dir : Path
        Folder of the prepared images.
    infos : list of ImageInfo
        The prepared images (SfM names, sizes, camera, EXIF focal length).
    camera_model : str
        COLMAP camera model: ``SIMPLE_RADIAL`` or ``RADIAL``.
    default_focal_factor : float
        Focal length prior as a multiple of the larger image side, where EXIF gives none.
    max_num_features : int
        Most SIFT features per image.
    num_threads : int
        CPU threads of the extraction.
    first_octave : int
        First SIFT octave: -1 or 0.
    estimate_affine_shape : bool
        Fit each keypoint's affine shape.
    domain_size_pooling : bool
        Pool each descriptor over a range of patch sizes.
    """
    groups: dict[tuple[int, int, str], list[ImageInfo]] = defaultdict(list)
    for info in infos:
        groups[(info.sfm_width, info.sfm_height, info.camera)].append(info)
    ext = pycolmap.FeatureExtractionOptions()
    ext.num_threads = num_threads
    ext.max_image_size = -1  # images are already downscaled by prepare_images
    ext.sift.max_num_features = max_num_features
    ext.sift.first_octave = first_octave
    ext.sift.estimate_affine_shape = bool(estimate_affine_shape)
    ext.sift.domain_size_pooling = bool(domain_size_pooling)
    for (w, h, cam), members in sorted(groups.items()):
        focals = np.array([m.focal_px for m in members], dtype=float)
        focals = focals[np.isfinite(focals)]
        f0 = float(np.median(focals)) if focals.size else default_focal_factor * max(w, h)
        reader = pycolmap.ImageReaderOptions()
        reader.camera_model = camera_model
        reader.camera_params = camera_params(camera_model, f0, w, h)
        log.info("extracting features of %d images of %dx%d px from %s (focal prior %.1f px)", len(members), w, h,
                 cam or "an unnamed camera", f0)
        pycolmap.extract_features(
            database,
            image_dir,
            image_names=[m.sfm_name for m in members],
            camera_mode=pycolmap.CameraMode.SINGLE,
            reader_options=reader,
            extraction_options=ext,
            device=pycolmap.Device.cpu,
        )


def choose_matching_method(method: str, n_images: int, exhaustive_max_images: int, n_priors: int) -> str:
    """Resolve ``auto``: exhaustive for small sets, spatial with GPS priors, else sequential.

    Parameters
    ----------
    method : str
        ``auto``, ``exhaustive``, ``sequential`` or ``spatial``.
    n_images : int
        Number of images.
    exhaustive_max_images : int
        Largest image count ``auto`` matches exhaustively.
    n_priors : int
        Number of images with a position prior.

    Returns
    -------
    str
        ``exhaustive``, ``sequential`` or ``spatial``.

    Raises
    ------
    InputError
        An unknown method, or ``spatial`` with fewer than two position priors.
    """
    if method == "auto":
        if n_images <= exhaustive_max_images:
            return "exhaustive"
        return "spatial" if n_priors >= 2 else "sequential"
    if method == "spatial" and n_priors < 2:
        raise InputError("sfm.matching.method is 'spatial' but fewer than two images have a GPS position (set sfm.matching.camera_log)")
    if method not in ("exhaustive", "sequential", "spatial"):
        raise InputError(f"sfm.matching.method: '{method}' is not one of auto, sequential, exhaustive, spatial")
    return method


def match_features(
    database: Path,
    n_images: int,
    method: str,
    overlap: int,
    exhaustive_max_images: int,
    num_threads: int,
    n_priors: int = 0,
    spatial_max_distance_m: float = 250.0,
    spatial_max_neighbors: int = 20,
    seed: int | None = None,
    guided_matching: bool = False,
) -> str:
    """Match features: exhaustive, sequential by capture order, or spatial by GPS position.

    ``method="auto"`` matches exhaustively up to ``exhaustive_max_images`` images (cheap
    and robust for small kite sets, where the flight path crosses itself); above that,
    spatially when position priors were written (each image with its
    ``spatial_max_neighbors`` nearest images within ``spatial_max_distance_m``, measured
    horizontally: a near-nadir photo's footprint is centred below the camera whatever its
    height, and height only sets the footprint's size, so a photo taken 300 m higher over
    the same ground must still be a neighbour; in 3-D it was not, and the full-size twin's
    epoch 2 lost its first 14 photos, taken while the kite climbed, as a separate model),
    else sequentially with ``overlap`` neighbours (quadratic overlap). Exhaustive matching
    costs O(n²) image pairs; spatial and sequential O(n·k). Returns the method used.

    ``seed`` (deterministic mode) seeds the RANSAC of the two-view verification; COLMAP
    otherwise seeds each worker thread's generator from the system's entropy.

    ``guided_matching`` matches each verified pair a second time, constrained by its
    estimated two-view geometry (epipolar distance), which recovers matches the ratio test
    dropped between views of very different tilt.

    Parameters
    ----------
    database : Path
        The COLMAP database with the features; the verified matches are written to it.
    n_images : int
        Number of images.
    method : str
        ``auto``, ``exhaustive``, ``sequential`` or ``spatial`` (:func:`choose_matching_method`).
    overlap : int
        Neighbours in capture order matched with each image (sequential).
    exhaustive_max_images : int
        Largest image count ``auto`` matches exhaustively.
    num_threads : int
        CPU threads of the matching.
    n_priors : int
        Number of images with a position prior in the database.
    spatial_max_distance_m : float
        Largest horizontal distance between the positions of a spatial pair (m).
    spatial_max_neighbors : int
        Most neighbours matched with each image (spatial).
    seed : int or None
        Seed of the verification's RANSAC, run on one thread; None = COLMAP's own seeds.
    guided_matching : bool
        Match each verified pair again, guided by its two-view geometry.

    Returns
    -------
    str
        The method used.

    Raises
    ------
    InputError
        An unknown method, or ``spatial`` with fewer than two position priors.
    """
    method = choose_matching_method(method, n_images, exhaustive_max_images, n_priors)
    mopt = pycolmap.FeatureMatchingOptions()
    mopt.num_threads = num_threads
    mopt.guided_matching = bool(guided_matching)
    vopt = pycolmap.TwoViewGeometryOptions()
    if seed is not None:
        vopt.ransac.random_seed = int(seed)
        vopt.ransac.num_threads = 1
    if method == "exhaustive":
        pycolmap.match_exhaustive(database, matching_options=mopt, verification_options=vopt, device=pycolmap.Device.cpu)
    elif method == "sequential":
        popt = pycolmap.SequentialPairingOptions()
        popt.overlap = overlap
        popt.quadratic_overlap = True
        popt.num_threads = num_threads
        pycolmap.match_sequential(database, matching_options=mopt, pairing_options=popt, verification_options=vopt,
                                  device=pycolmap.Device.cpu)
    else:  # spatial
        popt = pycolmap.SpatialPairingOptions()
        popt.ignore_z = True  # horizontal distance (see above)
        popt.max_distance = spatial_max_distance_m
        popt.max_num_neighbors = spatial_max_neighbors
        popt.num_threads = num_threads
        pycolmap.match_spatial(database, matching_options=mopt, pairing_options=popt, verification_options=vopt,
                               device=pycolmap.Device.cpu)
    return method


def why_no_model(database: Path, min_num_matches: int) -> str:
    """COLMAP's reason for building no model, read from the match database, as a clause.

    Distinguishes photos that share too few verified matches from photos that overlap but
    were taken from one spot (every verified pair a pure rotation: no baseline to
    triangulate from). O(number of image pairs).
    """
    db = pycolmap.Database.open(str(database))
    try:
        n_images = db.num_images()
        _, geoms = db.read_two_view_geometries()
    finally:
        db.close()
    C = pycolmap.TwoViewGeometryConfiguration
    inliers = [len(g.inlier_matches) for g in geoms]
    good = [g for g, n in zip(geoms, inliers) if n >= min_num_matches]
    if not good:
        best = max(inliers, default=0)
        return (f"no pair of the {n_images} photos shares {min_num_matches} verified feature matches (best pair: {best}); "
                "the photos do not overlap or show too little texture")
    rotation = {C.PANORAMIC, C.PLANAR_OR_PANORAMIC}
    if all(g.config in rotation for g in good):
        return (f"all {len(good)} overlapping photo pair(s) were taken from one spot (pure camera rotation: no baseline), "
                "so no 3-D point can be triangulated; take the photos from different positions")
    return (f"{len(good)} photo pair(s) overlap but COLMAP found no starting pair with enough baseline to triangulate; "
            "take photos from more positions with more overlap")


MAPPERS = ("incremental", "global", "hierarchical")
#: COLMAP's growth factor of the model between the incremental mapper's global adjustments
DEFAULT_GLOBAL_BA_GROWTH = 1.1


def _incremental_options(refine_principal_point: bool, min_num_matches: int, seed: int, num_threads: int,
                         global_ba_growth: float = DEFAULT_GLOBAL_BA_GROWTH) -> pycolmap.IncrementalPipelineOptions:
    """COLMAP's incremental pipeline options with self-calibration and every seed set.

    ``global_ba_growth``: a global bundle adjustment each time the registered frames or the
    points have grown by this factor (COLMAP's two ratios; see ``SfmParams``).
    """
    opts = pycolmap.IncrementalPipelineOptions()
    opts.ba_global_frames_ratio = global_ba_growth
    opts.ba_global_points_ratio = global_ba_growth
    opts.min_num_matches = min_num_matches
    opts.ba_refine_focal_length = True
    opts.ba_refine_principal_point = refine_principal_point
    opts.ba_refine_extra_params = True
    opts.num_threads = num_threads
    opts.mapper.num_threads = num_threads
    opts.random_seed = seed
    opts.mapper.random_seed = seed
    opts.triangulation.random_seed = seed
    return opts


def _global_options(refine_principal_point: bool, min_num_matches: int, seed: int,
                    num_threads: int) -> pycolmap.GlobalPipelineOptions:
    """GLOMAP-style global pipeline options: the same self-calibration, CPU solvers, seeded.

    COLMAP 4.2's global mapper ends with retriangulation, a global bundle adjustment with
    ``mapper.bundle_adjustment`` (here: focal length, principal point as configured and the
    radial terms refined, as the incremental mapper's final global BA) and an outlier filter.
    """
    opts = pycolmap.GlobalPipelineOptions()
    opts.min_num_matches = min_num_matches
    opts.num_threads = num_threads
    opts.random_seed = seed
    m = opts.mapper
    m.num_threads = num_threads
    m.random_seed = seed
    ba = m.bundle_adjustment
    ba.refine_focal_length = True
    ba.refine_principal_point = refine_principal_point
    ba.refine_extra_params = True
    ba.ceres.use_gpu = False
    m.global_positioning.use_gpu = False
    return opts


def _hierarchical_options(refine_principal_point: bool, min_num_matches: int, seed: int, num_threads: int,
                          global_ba_growth: float = DEFAULT_GLOBAL_BA_GROWTH) -> pycolmap.HierarchicalPipelineOptions:
    """COLMAP's partitioned pipeline: overlapping clusters mapped incrementally, then merged."""
    opts = pycolmap.HierarchicalPipelineOptions()
    opts.num_threads = num_threads
    opts.num_workers = max(1, min(num_threads, 2))
    inc = _incremental_options(refine_principal_point, min_num_matches, seed, max(1, num_threads // opts.num_workers),
                               global_ba_growth)
    inc.ba_refine_sensor_from_rig = False  # one camera per frame: no rig to refine (COLMAP warns it breaks merging)
    opts.incremental_options = inc
    return opts


def final_bundle_adjustment(rec: pycolmap.Reconstruction, refine_principal_point: bool, num_threads: int) -> None:
    """One global bundle adjustment of all poses, points and the shared intrinsics.

    The hierarchical mapper merges its clusters' models by similarity transforms and ends
    there; this adjustment gives the merged model the same final self-calibrating BA as the
    incremental and global mappers. O(iterations × (observations + images³)) with Schur.

    Parameters
    ----------
    rec : pycolmap.Reconstruction
        The model; adjusted in place.
    refine_principal_point : bool
        Refine the principal point too.
    num_threads : int
        CPU threads of the solver.
    """
    opts = pycolmap.BundleAdjustmentOptions()
    opts.refine_focal_length = True
    opts.refine_principal_point = refine_principal_point
    opts.refine_extra_params = True
    opts.ceres.use_gpu = False
    opts.ceres.solver_options.num_threads = num_threads
    pycolmap.bundle_adjustment(rec, opts)


def map_model(
    database: Path,
    image_dir: Path,
    out_dir: Path,
    refine_principal_point: bool,
    min_num_matches: int,
    seed: int,
    num_threads: int,
    source_dir: str | Path | None = None,
    mapper: str = "incremental",
    global_ba_growth: float = DEFAULT_GLOBAL_BA_GROWTH,
) -> pycolmap.Reconstruction:
    """Map the matched images into a model; returns the model with the most registered images.

    ``mapper``: ``incremental`` (COLMAP's incremental SfM: one image at a time with
    repeated global bundle adjustments, whose cost grows superlinearly with the image
    count), ``global`` (GLOMAP-style: rotation averaging and global positioning of all
    images at once, then a few global bundle adjustments) or ``hierarchical`` (the view
    graph split into overlapping clusters of at most 500 images, each mapped incrementally,
    then merged). Every mapper's model ends with a global bundle adjustment that refines
    the shared camera's focal length, radial distortion and (``refine_principal_point``)
    principal point. ``global_ba_growth`` sets how often the incremental mappers (also
    within hierarchical clusters) adjust the whole model (see ``SfmParams``).

    ``source_dir`` is the photo folder the user gave (named in errors instead of the
    prepared copies' work folder).

    Parameters
    ----------
    database : Path
        The COLMAP database with the verified matches.
    image_dir : Path
        Folder of the prepared images.
    out_dir : Path
        Folder the chosen model is written to (replaced if it exists); every model is first written to a
        sibling folder ``<out_dir>_all``, removed at the end.
    refine_principal_point : bool
        Refine the principal point in the bundle adjustments.
    min_num_matches : int
        Fewest verified matches for an image pair to be used.
    seed : int
        Seed of the mapper's random choices.
    num_threads : int
        CPU threads of the mapper.
    source_dir : path or None
        The user's photo folder, for error messages; None = ``image_dir``.
    mapper : str
        ``incremental``, ``global`` or ``hierarchical``.
    global_ba_growth : float
        Growth factor of the model between the incremental mapper's global adjustments.

    Returns
    -------
    pycolmap.Reconstruction
        The model with the most registered images.

    Raises
    ------
    InputError
        When no model could be built, with COLMAP's reason (:func:`why_no_model`).
    """
    if mapper not in MAPPERS:
        raise InputError(f"sfm.mapper: '{mapper}' is not one of {', '.join(MAPPERS)}")
    tmp = out_dir.parent / (out_dir.name + "_all")
    if tmp.exists():
        shutil.rmtree(tmp)
    tmp.mkdir(parents=True)
    args = (refine_principal_point, min_num_matches, seed, num_threads)
    if mapper == "incremental":
        models = pycolmap.incremental_mapping(database, image_dir, tmp, _incremental_options(*args, global_ba_growth))
    elif mapper == "global":
        models = pycolmap.global_mapping(database, image_dir, tmp, _global_options(*args))
    else:
        try:
            models = pycolmap.hierarchical_mapping(database, image_dir, tmp, _hierarchical_options(*args, global_ba_growth))
        except (RuntimeError, ValueError, IndexError):  # no cluster registered an image (COLMAP checks or indexes an empty list)
            models = {}
    models = {k: r for k, r in models.items() if r.num_reg_images() > 0}
    if not models:
        raise InputError(f"{source_dir or image_dir}: structure from motion built no model: {why_no_model(database, min_num_matches)}")
    for idx, rec in models.items():
        log.info("%s mapper, model %d: %d images, %d points", mapper, idx, rec.num_reg_images(), rec.num_points3D())
    best = max(models.values(), key=lambda r: r.num_reg_images())
    if mapper == "hierarchical":
        final_bundle_adjustment(best, refine_principal_point, num_threads)
    if mapper != "incremental":  # pixel errors after the last adjustment (global filters on normalised ones)
        best.update_point_3d_errors()
    if out_dir.exists():
        shutil.rmtree(out_dir)
    out_dir.mkdir(parents=True)
    best.write(out_dir)
    shutil.rmtree(tmp)
    return best


def run_sfm(
    infos: list[ImageInfo],
    image_dir: str | Path,
    work_dir: str | Path,
    model_dir: str | Path,
    params: SfmParams,
    seed: int,
    num_threads: int,
    positions: dict[str, np.ndarray] | None = None,
    source_dir: str | Path | None = None,
) -> tuple[pycolmap.Reconstruction, dict]:
    """Features, matching and mapping; returns the largest model and timings (s).

    ``positions`` (SfM file name → approximate camera position, m) enables spatial matching.
    With ``params.deterministic`` every step runs on one thread and every random
    choice (RANSAC of the two-view verification, the mapper's initial pair and image
    registration, triangulation) takes ``seed``: the same images and config then give
    the same model, bit for bit. COLMAP's worker threads otherwise draw their own seeds
    and finish in varying order, so a multi-threaded rerun differs slightly.

    Parameters
    ----------
    infos : list of ImageInfo
        The prepared images.
    image_dir : path
        Folder of the prepared images.
    work_dir : path
        Work folder; holds ``database.db``, which is recreated.
    model_dir : path
        Folder the model is written to.
    params : SfmParams
        The stage's parameters.
    seed : int
        Seed of COLMAP's random choices.
    num_threads : int
        CPU threads (1 with ``params.deterministic``).
    positions : mapping or None
        Approximate camera position (m) keyed by SfM file name; None = no position priors.
    source_dir : path or None
        The user's photo folder, for error messages.

    Returns
    -------
    rec : pycolmap.Reconstruction
        The model with the most registered images.
    timings : dict
        Time of each step (s), the matching method and mapper used, the number of position priors and the
        keypoint counts.
    """
    image_dir, work_dir, model_dir = Path(image_dir), Path(work_dir), Path(model_dir)
    deterministic = bool(params.deterministic)
    if deterministic:
        num_threads = 1
        log.info("deterministic SfM: one thread, seed %d", seed)
    work_dir.mkdir(parents=True, exist_ok=True)
    database = work_dir / "database.db"
    if database.exists():
        database.unlink()
    pycolmap.set_random_seed(seed)
    t0 = time.perf_counter()
    extract_features(
        database, image_dir, infos, params.camera_model, params.default_focal_factor,
        params.max_num_features, num_threads, params.first_octave,
        params.estimate_affine_shape, params.domain_size_pooling,
    )
    capped = cap_features(database, params.max_num_features)
    t1 = time.perf_counter()
    m = params.matching
    n_priors = write_position_priors(database, positions, m.gps_sigma_m) if positions else 0
    used = match_features(
        database, len(infos), m.method, m.overlap, m.exhaustive_max_images, num_threads,
        n_priors, m.spatial_max_distance_m, m.spatial_max_neighbors, seed if deterministic else None,
        params.guided_matching,
    )
    t2 = time.perf_counter()
    rec = map_model(
        database, image_dir, model_dir, params.refine_principal_point, params.min_num_matches, seed, num_threads,
        source_dir, params.mapper, params.global_ba_growth,
    )
    t3 = time.perf_counter()
    timings = {
        "features_s": t1 - t0, "matching_s": t2 - t1, "mapping_s": t3 - t2, "matching_method": used,
        "n_position_priors": n_priors, "deterministic": deterministic, "mapper": params.mapper,
        "global_ba_growth": params.global_ba_growth,
        "keypoints_extracted": capped["keypoints_before"], "keypoints_kept": capped["keypoints_after"],
        "images_feature_capped": capped["images_capped"],
        "estimate_affine_shape": params.estimate_affine_shape, "domain_size_pooling": params.domain_size_pooling,
        "guided_matching": params.guided_matching,
    }
    log.info("features %.1f s, matching (%s) %.1f s, mapping (%s) %.1f s", t1 - t0, used, t2 - t1, params.mapper, t3 - t2)
    return rec, timings
