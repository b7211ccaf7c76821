"""The closerange stage's products, one function per rule (Mayr et al. 2016, paper 001, Table 1).

* :func:`photograph_scene` (rule ``closerange_photos``, twin side): the pole-camera photos
  of one generated scene (it reads the scene's truth to build them, like the flight stage).
* :func:`photogrammetric_orthophoto` (rule ``closerange_sfm``, pipeline side: photos and
  the sphere survey only): SfM with self-calibration (the sfm stage's
  :func:`~kitegully.sfm.reconstruct_model`), sphere centres measured in the photos and
  triangulated, similarity to the survey, dense points by pairwise SGM, 2 cm DEM and
  orthophoto by the 25 % trimmed mean cropped by the camera circle, holes filled, the
  folding rule's legs measured.
* :func:`~kitegully.closerange.tables.closerange_tables` (rule ``closerange_summary``):
  Table 1 next to the paper's and the OBIA accuracy on these orthophotos next to the direct
  renders' and the paper's.

The parts :func:`photogrammetric_orthophoto` calls: the photographs (:mod:`.photos`), the
sphere georeferencing (:mod:`.markers`), dense points (:mod:`.dense`), gridding, outlier
removal and hole filling (:mod:`.gridding`) and the folding rule (:mod:`.foldrule`,
:mod:`.rule_photos`).
"""

from __future__ import annotations

import dataclasses
import logging
import time
from dataclasses import dataclass, field, fields
from datetime import datetime, timedelta
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping

import numpy as np
import pandas as pd

from kitegully import InputError
from kitegully.closerange.dense import PairMatching, dense_points
from kitegully.closerange.foldrule import measure_rule
from kitegully.closerange.gridding import fill_holes, grid_points, near_median_surface
from kitegully.closerange.markers import georeference_on_spheres
from kitegully.closerange.model import read_oriented_photos
from kitegully.closerange.photos import original_photos, read_photos
from kitegully.closerange.spheres import SphereDetection
from kitegully.config import config_section
from kitegully.io.raster import GridSpec, write_raster

if TYPE_CHECKING:
    from kitegully.twin.camera import Pose
    from kitegully.twin.polewalk import PoleScene, PoleWalk

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class CloseRangeParams:
    """Parameters of the closerange stage (config section ``closerange``).

    Attributes
    ----------
    scenes : tuple of str or "all"
        Scenes built by the run (``make closerange`` sets ``all``). [I] one scene keeps the
        default run inside its 20 min budget.
    scenes_without_rule : tuple of str
        Scenes photographed without the folding rule. [P] scene 6.
    walk : dict
        :class:`kitegully.twin.polewalk.PoleWalk` keys (photos per scene, image size, pole height, jitter).
    spheres : SphereDetection
        Sphere detection parameters.
    sfm_max_num_features : int
        SIFT features per photo for the SfM (the rest of the sfm stage's settings is reused,
        with exhaustive matching: a ring of photos has no GPS log).
    sfm_affine_features : str
        When the SfM uses affine-covariant SIFT (the sfm stage's ``estimate_affine_shape``
        and ``domain_size_pooling``) with guided matching: ``never``, ``always``, or
        ``fallback`` (plain SIFT first; if its model leaves any photo out, or builds none,
        the SfM is redone with affine-covariant features and that model is kept). [I] the
        walk's geometry: a pole camera at grazing angle γ to the slope sees the ground with
        tilt ``t = 1/sin γ``, and two photos Δφ apart around the ring differ by the
        transition tilt τ with ``τ + 1/τ = 2 + (t − 1/t)² sin²Δφ``; plain SIFT is
        similarity-invariant only and its matches collapse near τ ≈ 2, i.e. beyond
        ``sin Δφ* = √0.5 / (t − 1/t)``. On the twin's walks (10° steps, ±4.2° per step from
        the 3° per-photo scatter) γ is 18–31° in all scenes but 06, so Δφ* is 13–25° and
        1–11 of the 36 steps pass it (``benchmarks/closerange_walk_geometry.py``); whether
        the ring still closes depends on the next-but-one links, so the photos decide:
        a ring in which a neighbour link fails still registers every photo through the
        others, a ring that leaves photos out has broken at such links (scene 08: 11 of 36
        with plain SIFT, 36 with affine). ``fallback`` pays the several-times extraction
        cost (CPU only) only in those scenes, not in the default run's scene 10.
    sphere_tolerance_m : float
        Ray–point distance that still counts as one sphere, in the model's scale expressed
        at the walk's size (scaled by the camera ring radius / 5 m). [I] a tenth of the 0.1 m
        sphere radius: 0.3 px at 5 m is 2 mm, so 1 cm is lenient yet spheres are metres apart.
        Session 6 found it too tight for sunlit spheres (the shaded limb biased each photo's
        centre towards the sun; rays from opposite sides missed by 2–4 cm); the detector now
        fits only the lit limb, and scene 10 triangulates all 4 spheres. A sphere can still be
        split in two candidates (scene 05's S2); the pairing treats copies correctly.
    marker_budget_m : float
        Largest residual of a sphere after the similarity; an assignment of triangulated
        spheres to the survey is accepted only within it (and the inter-sphere distances must
        agree up to scale within twice it). [I] the survey's accuracy: 3.4 σ (99 % of a 3-D
        error) of the twin's 1.5 cm per axis is 5 cm; the paper's RTK ±10 cm effective (001)
        would give 0.10 m, too lenient for the twin (a 3-sphere chance fit in scene 05).
    pole_height_m, sphere_radius_m : float
        Height of the camera above the ground and the spheres' radius (acquisition record;
        the rule passes ``walk.pole_height_m`` and ``obia.scenes.marker_radius_m``). A sphere
        assignment is plausible only if it puts the cameras' median height above the plane
        of the surveyed sphere feet within a factor 2 of the pole. [I] the ground around the
        ring departs from that plane by the scene's undulation (decimetres), far less than
        a factor 2 of 3 m; a false fit changes the scale by much more (scene 05: ×8).
    dense : PairMatching
        Pairwise semi-global matching.
    trim : float
        Share cut from each tail of a cell's heights. [P] 25 % ([I] per tail).
    periphery : str
        ``circle`` or ``hull`` of the camera positions (the crop, instead of the paper's hand crop).
    fill_holes_cells : int
        Holes inside the crop up to this size (cells) are filled from their rim (in-painting,
        as PhotoScan's mesh interpolates); larger gaps stay nodata and are left out of the
        classification. [I] 2500 cells = 1 m².
    outlier_cell_m, outlier_tolerance_m : float
        Dense points farther than the tolerance from the median height of their coarse
        cell are dropped before gridding (mismatches onto the sky or the far hillside).
        [I] 10 cm cells (5 × 2 cm), 15 cm: half the relief a scarp builds inside one such
        cell on a 35° slope is below it, a mismatch metres off is not.
    min_dense_points : int
        Fewer dense points than this stops the scene with one sentence.
    rule_paint_rgb : tuple of float
        The folding rule's yellow (tone-encoded 0–1, full light). [I] the rule's known
        paint (a yellow folding rule), as a GCP sphere's radius is known.
    rule_min_paint_fraction : float
        Least share of a 2 cm cell covered by the paint for the cell to count as rule
        (linear unmixing against the 9-cell median background). [I] a strip one cell wide
        covers at least half of one cell in every row across it, so 0.25 is the midpoint
        between no paint and that guaranteed half (replaces a saturation threshold that had
        been set on scene 10).  Used by the orthophoto fallback (below).
    rule_strip_width_m : float
        Width of the rule's painted strip. [P] 2 cm.  The rule is measured in the photos
        (:mod:`kitegully.closerange.rule_photos`): the widest the strip can appear is its
        width at the pole's height (800 px focal length: 5.3 px), which sets the median
        background window (4 ×: the strip fills at most a quarter of it), the line and
        grouping tolerances, and the triangulation tolerance of its corner and leg ends (the
        strip's width: wherever it is resolved, a point on it is located within its width).
        Where the photos give no rule, the orthophoto method (``rule_min_paint_fraction``)
        is tried; the record's ``rule_method`` says which one measured it.
    on_scene_failure : str
        ``stop`` (default): a scene that cannot be georeferenced stops the run with its one
        sentence (InputError). ``record`` (``make closerange``): the sentence is logged and
        written as the scene's record (:func:`~kitegully.closerange.tables.failed_scene_record`), the scene is skipped
        downstream and listed as ``failed`` in the summary. [I] in a 10-scene study a scene
        that cannot be georeferenced is a result (001 reports per-scene numbers); a single
        scene run has nothing to summarise, so it stops.
    """

    scenes: tuple[str, ...] | str = ("scene_10",)
    scenes_without_rule: tuple[str, ...] = ("scene_06",)
    walk: Mapping[str, Any] = field(default_factory=dict)
    spheres: SphereDetection = SphereDetection()
    sfm_max_num_features: int = 4096
    sfm_affine_features: str = "never"
    sphere_tolerance_m: float = 0.01
    marker_budget_m: float = 0.05
    pole_height_m: float = 3.0
    sphere_radius_m: float = 0.10
    dense: PairMatching = PairMatching()
    trim: float = 0.25
    periphery: str = "circle"
    fill_holes_cells: int = 2500
    outlier_cell_m: float = 0.1
    outlier_tolerance_m: float = 0.15
    min_dense_points: int = 10000
    rule_paint_rgb: tuple[float, float, float] = (0.93, 0.80, 0.20)
    rule_min_paint_fraction: float = 0.25
    rule_strip_width_m: float = 0.02
    on_scene_failure: str = "stop"

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any]) -> "CloseRangeParams":
        """Build from the ``closerange`` section (or the part a rule passes); bad keys raise InputError."""
        config_section(cfg, "closerange", (), optional=cls.__dataclass_fields__)
        v: dict[str, Any] = {}
        for k, x in cfg.items():
            if k == "scenes":
                v[k] = "all" if x == "all" else tuple(str(s) for s in x)
            elif k == "scenes_without_rule":
                v[k] = tuple(str(s) for s in x)
            elif k == "rule_paint_rgb":
                v[k] = tuple(float(c) for c in x)
                if len(v[k]) != 3 or not all(0 < c <= 1 for c in v[k]):
                    raise InputError(f"closerange.rule_paint_rgb: {list(x)} is not three values in (0, 1]")
            elif k == "walk":
                v[k] = dict(x)
            elif k == "spheres":
                v[k] = SphereDetection.from_config(x)
            elif k == "dense":
                config_section(x, "closerange.dense", (), optional={f.name for f in fields(PairMatching)})
                v[k] = PairMatching(**{n: type(getattr(PairMatching, n))(y) for n, y in x.items()})
            else:
                v[k] = type(getattr(cls, k))(x)
        p = cls(**v)
        if not 0 <= p.trim < 0.5:
            raise InputError(f"closerange.trim: {p.trim} is not in [0, 0.5) (share cut from each tail)")
        if p.periphery not in ("circle", "hull"):
            raise InputError(f"closerange.periphery: '{p.periphery}' is not one of circle, hull")
        if p.sfm_affine_features not in ("never", "fallback", "always"):
            raise InputError(f"closerange.sfm_affine_features: '{p.sfm_affine_features}' is not one of never, fallback, always")
        if p.on_scene_failure not in ("stop", "record"):
            raise InputError(f"closerange.on_scene_failure: '{p.on_scene_failure}' is not one of stop, record")
        if p.rule_strip_width_m <= 0:
            raise InputError(f"closerange.rule_strip_width_m: {p.rule_strip_width_m} is not a positive width (m)")
        if p.dense.block_size_px % 2 == 0 or p.dense.downscale < 1:
            raise InputError("closerange.dense: block_size_px must be odd and downscale at least 1")
        return p


# --------------------------------------------------------------------------- closerange_photos
def scene_walk(
    ortho_path: str, dem_path: str, truth_markers_path: str, truth_eroded_path: str, meta: dict, markers: pd.DataFrame,
    walk_cfg: Mapping[str, Any], sphere_radius_m: float, folding_rule: bool, seed: int, scene: str,
) -> tuple[PoleScene, PoleWalk, list[Pose]]:
    """The photographed world and the pole walk of one scene: ``(PoleScene, PoleWalk, poses)`` (twin side).

    What :func:`photograph_scene` renders; also read by the walk-geometry benchmark
    (``benchmarks/closerange_walk_geometry.py``) without rendering.

    Parameters
    ----------
    ortho_path, dem_path : str
        The scene's orthophoto and DEM.
    truth_markers_path, truth_eroded_path : str
        The scene's truth masks of the marker spheres and of the eroded area.
    meta : dict
        Scene parameters and the reference eroded area (m²).
    markers : DataFrame
        Observed marker centres ``gcp_id, x, y, z, radius_m``.
    walk_cfg : mapping
        The pole walk's config section (:meth:`PoleWalk.from_config`).
    sphere_radius_m : float
        Radius of the marker spheres (m).
    folding_rule : bool
        Lay the folding rule in the scene.
    seed : int
        Master seed; the rule's placement and the walk draw their own streams from it.
    scene : str
        Scene name.

    Returns
    -------
    pscene : PoleScene
        The photographed world.
    walk : PoleWalk
        The walk's settings.
    poses : list of Pose
        Camera poses on the ring.
    """
    from kitegully.obia.scene import read_scene_rasters
    from kitegully.seeds import rng_for
    from kitegully.twin.closerange import CloseRangeScene
    from kitegully.twin.polewalk import PoleWalk, prepare_pole_scene, walk_poses

    rgb, dem, grid, (tm, te) = read_scene_rasters(ortho_path, dem_path, truth_markers_path, truth_eroded_path)
    sc = CloseRangeScene(scene, grid, rgb, dem, te, tm, markers, meta)
    ps = prepare_pole_scene(sc, sphere_radius_m, folding_rule, rng_for(seed, "closerange", scene, "rule"))
    # the photographer walks around the patch *and* the spheres (001: GCPs around the eroded
    # area, all in the photos): the ring encloses the farthest sphere too
    # (where that ring would leave the rendered ground it follows the ground's edge, but stays
    # outside the patch: spheres beyond it are photographed from the far side of the ring)
    sphere_reach = float(np.hypot(*(ps.spheres[:, :2] - ps.patch_centre).T).max()) if len(ps.spheres) else 0.0
    walk = PoleWalk.from_config(walk_cfg)
    min_radius = ps.patch_reach_m + walk.standoff_m
    ps = dataclasses.replace(ps, patch_reach_m=max(ps.patch_reach_m, sphere_reach))
    poses = walk_poses(ps, walk, rng_for(seed, "closerange", scene, "walk"), min_radius_m=min_radius)
    return ps, walk, poses


def photograph_scene(
    ortho_path: str, dem_path: str, truth_markers_path: str, truth_eroded_path: str, meta: dict, markers: pd.DataFrame,
    walk_cfg: Mapping[str, Any], sphere_radius_m: float, folding_rule: bool, seed: int, scene: str, photo_dir: str | Path,
) -> dict:
    """Render the pole walk of one scene into ``photo_dir`` (JPEG with EXIF); return the truth record.

    Twin side: the scene's truth (marker mask, eroded mask) builds the photographed world.
    Returns ``{"n_images", "camera_centres", "spheres", "rule", "render_s"}`` (truth, for
    the evaluation only).

    Parameters
    ----------
    ortho_path, dem_path : str
        The scene's orthophoto and DEM.
    truth_markers_path, truth_eroded_path : str
        The scene's truth masks of the marker spheres and of the eroded area.
    meta : dict
        Scene parameters and the reference eroded area (m²).
    markers : DataFrame
        Observed marker centres ``gcp_id, x, y, z, radius_m``.
    walk_cfg : mapping
        The pole walk's config section (:meth:`PoleWalk.from_config`).
    sphere_radius_m : float
        Radius of the marker spheres (m).
    folding_rule : bool
        Lay the folding rule in the scene.
    seed : int
        Master seed; the rule's placement, the walk and the photos draw their own streams from it.
    scene : str
        Scene name.
    photo_dir : str or Path
        Folder the photos are written to (created if missing).

    Returns
    -------
    dict
        Truth record: ``scene``, ``n_images``, ``render_s`` (s), ``camera_centres``, ``spheres`` and ``rule``
        (None without a rule).
    """
    from kitegully.seeds import rng_for
    from kitegully.twin.exif import exif_bytes, write_jpeg
    from kitegully.twin.polewalk import photograph_walk

    t0 = time.perf_counter()
    ps, walk, poses = scene_walk(ortho_path, dem_path, truth_markers_path, truth_eroded_path, meta, markers, walk_cfg,
                                 sphere_radius_m, folding_rule, seed, scene)
    cam = walk.camera()
    out = Path(photo_dir)
    out.mkdir(parents=True, exist_ok=True)
    when = datetime(2015, 7, 14, 10, 0, 0)
    for i, img in photograph_walk(ps, walk, poses, rng_for(seed, "closerange", scene, "photos")):
        write_jpeg(out / f"IMG_{i:04d}.JPG", img, exif_bytes(cam, when + timedelta(seconds=5 * i)), 95)
    dt = time.perf_counter() - t0
    log.info("%s: %d photos rendered in %.0f s (%.1f s each)", scene, len(poses), dt, dt / len(poses))
    return {
        "scene": scene, "n_images": len(poses), "render_s": dt,
        "camera_centres": [p.C.tolist() for p in poses], "spheres": ps.spheres.tolist(),
        "rule": None if ps.rule is None else ps.rule.tolist(),
    }


def photogrammetric_orthophoto(
    photo_dir: str | Path, survey: pd.DataFrame, survey_path: str, grid: GridSpec, sfm_cfg: Mapping[str, Any],
    params: CloseRangeParams, seed: int, threads: int, scene: str, work_dir: str | Path, out: Mapping[str, str],
) -> dict:
    """Photos + sphere survey → SfM model in the survey frame → 2 cm DEM and orthophoto; returns the Table 1 record.

    Parameters
    ----------
    photo_dir : folder of the scene's photos.
    survey : surveyed sphere centres (``gcp_id, x, y, z``); ``survey_path`` names it in messages.
    grid : the scene's mapping frame (2 cm cells).
    sfm_cfg : the sfm stage's section (``max_num_features`` and matching are overridden).
    params : stage parameters. seed, threads : SfM seed and threads.
    work_dir : SfM work folder. out : paths ``model, summary, images, image_info, orthophoto, dem, spheres``.

    Raises
    ------
    InputError
        The photos do not connect into one model (the sfm stage's sentence), fewer than 3
        spheres triangulated, or too few dense points.
    """
    from kitegully.sfm import SfmParams, reconstruct_model

    t0 = time.perf_counter()
    if not {"gcp_id", "x", "y", "z"} <= set(survey.columns):
        raise InputError(f"{survey_path}: needs columns gcp_id, x, y, z")
    photo_dir = Path(photo_dir)
    s = dict(sfm_cfg, max_num_features=params.sfm_max_num_features)
    s["matching"] = dict(s["matching"], camera_log=None, method="exhaustive")
    affine = params.sfm_affine_features == "always"
    sift_note = "affine" if affine else "plain"

    def sfm(affine_: bool) -> dict:
        s_ = dict(s, estimate_affine_shape=affine_, domain_size_pooling=affine_, guided_matching=affine_)
        return reconstruct_model(photo_dir, work_dir, out["model"], out["summary"], out["images"], out["image_info"],
                                 SfmParams.from_config(s_), seed, threads)

    try:
        summary = sfm(affine)
        plain_short = summary["n_registered"] < summary["n_images"]
        plain_result = f"{summary['n_registered']}/{summary['n_images']} photos registered"
    except InputError as err:
        if affine or params.sfm_affine_features != "fallback":
            raise
        plain_short, plain_result = True, f"no model ({err})"
    if plain_short and not affine and params.sfm_affine_features == "fallback":
        # the ring broke at azimuth steps beyond plain SIFT's affine limit: affine-covariant features
        log.info("%s: plain SIFT: %s; SfM again with affine-covariant SIFT and guided matching "
                 "(closerange.sfm_affine_features: fallback)", scene, plain_result)
        affine, sift_note = True, f"affine (fallback; plain SIFT: {plain_result})"
        summary = sfm(True)
    t_sfm = time.perf_counter() - t0
    photos, sparse = read_oriented_photos(out["model"])
    images = read_photos(Path(work_dir) / "images", [p.name for p in photos])  # the prepared copies SfM saw
    # spheres: detect, rays, triangulate, pair with the survey, similarity
    geo = georeference_on_spheres(photos, images, sparse, survey, params, f"{photo_dir}", scene)
    sim, rows, perm, res, found, checks, ids = geo.sim, geo.rows, geo.perm, geo.res, geo.found, geo.checks, geo.ids
    found_all, det_rows, centres = geo.found_all, geo.detections, geo.centres
    err = np.linalg.norm(res, axis=1)
    sph = pd.DataFrame({
        "gcp_id": [ids[p] for p in perm], "n_photos": [len(found[r][1]) for r in rows],
        "dx_m": res[:, 0], "dy_m": res[:, 1], "dz_m": res[:, 2], "error_m": err,
        "radius_m": [sim.scale * checks[r]["radius"] for r in rows],
        "height_above_tie_points_m": [sim.scale * checks[r]["height"] for r in rows],
    })
    sph.to_csv(out["spheres"], index=False, float_format="%.4f")
    log.info("%s: %d spheres triangulated, %d paired with the survey, marker error %.3f m (max %.3f m), scale %.4f",
             scene, len(found), len(rows), err.mean(), err.max(), sim.scale)
    t1 = time.perf_counter()
    xyz_m, rgb, n_pairs = dense_points(photos, images, sparse, params.dense)
    xyz = sim.apply(xyz_m)
    t2 = time.perf_counter()
    if len(xyz) < params.min_dense_points:
        raise InputError(f"{photo_dir}: dense matching gave {len(xyz)} points (< {params.min_dense_points}); the photos overlap too little")
    keep = near_median_surface(xyz, grid, params.outlier_cell_m, params.outlier_tolerance_m)
    log.info("%s: %d of %d dense points kept within %.2f m of the %.2f m median surface", scene, keep.sum(), len(keep),
             params.outlier_tolerance_m, params.outlier_cell_m)
    xyz, rgb = xyz[keep], rgb[keep]
    cams_w = sim.apply(centres)
    surf = grid_points(xyz, grid, rgb, params.trim, cams_w[:, :2], params.periphery)
    from kitegully.closerange.gridding import periphery_mask

    inside = periphery_mask(grid, cams_w[:, :2], params.periphery)
    holes_before = int((~np.isfinite(surf.dem) & inside).sum())
    dem, ortho, filled = fill_holes(surf.dem, surf.ortho, inside, params.fill_holes_cells)
    from kitegully.seeds import rng_for

    rule_images = original_photos(photo_dir, out["image_info"], images)
    rule, rule_method, rule_note = measure_rule(photos, rule_images, sim, ortho, dem, grid, params,
                                                rng_for(seed, "closerange", scene, "rule_photos"),
                                                rng_for(seed, "closerange", scene, "rule_ransac"))
    write_raster(out["orthophoto"], ortho, grid, nodata=None, band_names=["red", "green", "blue"])
    write_raster(out["dem"], dem.astype(np.float32), grid)
    t3 = time.perf_counter()
    n_inside = int(inside.sum())
    record = {
        "scene": scene, "status": "ok",
        "images_used": int(summary["n_images"]), "images_aligned": int(summary["n_registered"]),
        "sift": sift_note,
        "marker_error_m": float(err.mean()), "marker_error_max_m": float(err.max()),
        "spheres_measured": len(rows), "sphere_detections": len(det_rows),
        "sphere_candidates": len(found_all), "sphere_candidates_round": len(found),
        "scale_error_pct": None if rule is None else rule["scale_error_pct"],
        "rule": rule, "rule_method": rule_method, "rule_note": rule_note,
        "tie_points": int(summary["n_points3d"]), "reprojection_px": float(summary["mean_reprojection_error_px"]),
        "dense_points": int(len(xyz)), "dense_pairs": int(n_pairs),
        "cells_in_crop": n_inside, "holes_pct": 100.0 * holes_before / max(n_inside, 1),
        "holes_filled_pct": 100.0 * filled / max(n_inside, 1),
        "similarity_scale": float(sim.scale),
        "timings_s": {"sfm": t_sfm, "spheres": t1 - t0 - t_sfm, "dense": t2 - t1, "grid": t3 - t2, "total": t3 - t0},
    }
    log.info("%s: %d/%d photos aligned, %d tie points, %d dense points, holes %.1f %% of the crop, scale error %s, %.0f s",
             scene, record["images_aligned"], record["images_used"], record["tie_points"], record["dense_points"],
             record["holes_pct"], "n/a" if rule is None else f"{rule['scale_error_pct']:.2f} % (rule measured in the {rule_method})",
             t3 - t0)
    return record


