"""The closerange stage's products, one function per rule (Mayr et al. 2016, paper 001, Table 1).

* :func:`photograph_scene` (rule ``closerange_photos``, twin side): the pole-camera photos
  of one generated scene (it reads the scene's truth to build them, like the flight stage).
* :func:`photogrammetric_orthophoto` (rule ``closerange_sfm``, pipeline side: photos and
  the sphere survey only): SfM with self-calibration (the sfm stage's
  :func:`~kitegully.sfm.reconstruct_model`), sphere centres measured in the photos and
  triangulated, similarity to the survey, dense points by pairwise SGM, 2 cm DEM and
  orthophoto by the 25 % trimmed mean cropped by the camera circle, holes filled, the
  folding rule's legs measured.
* :func:`closerange_tables` (rule ``closerange_summary``): Table 1 next to the paper's and
  the OBIA accuracy on these orthophotos next to the direct renders' and the paper's.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import time
from dataclasses import dataclass, field, fields
from datetime import datetime, timedelta
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping, Sequence

import cv2
import numpy as np
import pandas as pd
from scipy import ndimage

from kitegully import InputError
from kitegully.closerange.dense import PairMatching, dense_points
from kitegully.closerange.foldrule import measure_folding_rule
from kitegully.closerange.gridding import grid_points
from kitegully.closerange.model import detection_rays, match_markers, read_oriented_photos, triangulate_spheres, verify_spheres
from kitegully.closerange.spheres import SphereDetection, detect_spheres
from kitegully.config import config_section
from kitegully.georef.similarity import Similarity
from kitegully.io.raster import GridSpec, write_raster

if TYPE_CHECKING:
    from kitegully.twin.camera import Pose
    from kitegully.twin.polewalk import PoleScene, PoleWalk

log = logging.getLogger(__name__)

#: 001 Table 1 (scenes 1-10): images used / aligned, marker error (m), scale error (%; None: no rule in scene 6).
PAPER_TABLE1 = pd.DataFrame({
    "scene": [f"scene_{i:02d}" for i in range(1, 11)],
    "paper_images_used": [613, 539, 676, 480, 342, 243, 179, 279, 406, 251],
    "paper_images_aligned": [546, 484, 505, 342, 234, 233, 143, 275, 399, 250],
    "paper_marker_error_m": [0.03, 0.03, 0.01, 0.08, 0.16, 0.04, 0.02, 0.03, 0.03, 0.03],
    "paper_scale_error_pct": [1, 2, 3, 1, 6, np.nan, 1, 1, 2, 2],
})
#: 001 Table 3 overall accuracy per scene (%) and over all scenes.
PAPER_OA = dict(zip([f"scene_{i:02d}" for i in range(1, 11)], [95.4, 95.4, 92.8, 94.5, 90.7, 94.3, 92.6, 94.3, 93.3, 95.5]))
PAPER_OA["all"] = 94.3


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
        written as the scene's record (:func:`failed_scene_record`), the scene is skipped
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


# --------------------------------------------------------------------------- closerange_sfm
def _read_photos(photo_dir: Path, names: Sequence[str]) -> dict[str, np.ndarray]:
    out = {}
    for n in names:
        img = cv2.imread(str(photo_dir / n), cv2.IMREAD_COLOR)
        if img is None:
            raise InputError(f"{photo_dir / n}: cannot read the photo")
        out[n] = cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
    return out


def _original_photos(photo_dir: Path, image_info_path: str | Path, prepared: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The photographer's files where they are the SfM's pixel grid (orientation 1, scale 1), else the prepared copies.

    The prepared copies (:func:`kitegully.sfm.images.prepare_images`) are re-encoded with
    4:2:0 chroma subsampling, which halves the colour resolution: a 1–2 px yellow strip
    loses most of its colour there (scene 09: no L in any prepared copy, L's in the
    originals), while the originals (4:4:4 at quality 95) keep it.  The sphere detection
    keeps the prepared copies (not changed here).
    """
    with open(image_info_path, encoding="utf-8") as fh:
        info = {r["sfm_name"]: r for r in json.load(fh)}
    out = {}
    for name, img in prepared.items():
        r = info.get(name)
        if r is not None and int(r.get("orientation", 1)) == 1 and float(r.get("scale", 1.0)) == 1.0:
            orig = cv2.imread(str(photo_dir / r["name"]), cv2.IMREAD_COLOR)
            if orig is not None and orig.shape[:2] == img.shape[:2]:
                out[name] = cv2.cvtColor(orig, cv2.COLOR_BGR2RGB)
                continue
        out[name] = img
    return out


def _fill_holes(dem: np.ndarray, ortho: np.ndarray, inside: np.ndarray, max_cells: int) -> tuple[np.ndarray, np.ndarray, int]:
    """Fill nodata holes inside the crop up to ``max_cells`` from their rim; return the count filled."""
    holes = ~np.isfinite(dem) & inside
    lab, n = ndimage.label(holes)
    if n == 0:
        return dem, ortho, 0
    sizes = np.bincount(lab.ravel())
    small = (sizes <= max_cells)
    small[0] = False
    fill = small[lab]
    if not fill.any():
        return dem, ortho, 0
    known = np.isfinite(dem)
    idx = ndimage.distance_transform_edt(~known, return_distances=False, return_indices=True)
    dem2 = dem.copy()
    dem2[fill] = dem[tuple(i[fill] for i in idx)]
    mask = fill.astype(np.uint8)
    img = np.ascontiguousarray(np.moveaxis(ortho, 0, -1))
    img = cv2.inpaint(img, mask, 3, cv2.INPAINT_TELEA)
    ortho2 = ortho.copy()
    ortho2[:, fill] = np.moveaxis(img, -1, 0)[:, fill]
    return dem2, ortho2, int(fill.sum())


def _near_median_surface(xyz: np.ndarray, grid: GridSpec, cell_m: float, tolerance_m: float) -> np.ndarray:
    """Points within ``tolerance_m`` of the per-cell median height on a coarse grid (mismatches, sky, the far hillside)."""
    from kitegully.closerange.gridding import trimmed_cell_means

    k = max(1, int(round(cell_m / grid.cell)))
    w, h = -(-grid.width // k), -(-grid.height // k)
    col = np.floor((xyz[:, 0] - grid.x0) / (grid.cell * k)).astype(np.int64)
    row = np.floor((grid.y0 - xyz[:, 1]) / (grid.cell * k)).astype(np.int64)
    inside = (row >= 0) & (row < h) & (col >= 0) & (col < w)
    idx = np.where(inside, row * w + col, 0)
    med, _, _ = trimmed_cell_means(idx[inside], xyz[inside, 2], w * h, 0.45)
    dev = np.full(len(xyz), np.inf)
    dev[inside] = np.abs(xyz[inside, 2] - med[idx[inside]])
    return dev <= tolerance_m


def measure_rule(
    photos: Sequence[Any], images: Mapping[str, np.ndarray], sim: Any, ortho: np.ndarray, dem: np.ndarray, grid: GridSpec,
    params: CloseRangeParams, rng_photos: np.random.Generator, rng_ortho: np.random.Generator,
) -> tuple[dict | None, str | None, str]:
    """The folding rule's legs: measured in the photos (triangulated), else in the orthophoto; (rule, method, note).

    ``method`` is ``"photos"``, ``"orthophoto"`` or None (not found); ``note`` says why the
    photos gave no rule (empty when they did).  The photo method is the primary one: the
    2 cm strip is 1–5 px wide in the photos and smeared below any defensible paint share in
    the 2 cm orthophoto (README, closerange); the orthophoto's own threshold (a 1-cell strip
    covers at least half a cell) stays principled, so it is kept as the fallback.

    Parameters
    ----------
    photos : sequence of OrientedPhoto
        Oriented photos of the scene (model frame).
    images : mapping
        RGB photo (rows, cols, 3) uint8 of each photo name.
    sim : Similarity
        Model → survey frame (the sphere similarity).
    ortho : ndarray (3, rows, cols) uint8
        Photogrammetric orthophoto.
    dem : ndarray (rows, cols) float
        Photogrammetric DEM (m, NaN = no data).
    grid : GridSpec
        Grid of ``ortho`` and ``dem``.
    params : CloseRangeParams
        Stage settings; reads the ``rule_*`` settings, ``pole_height_m`` and ``outlier_tolerance_m``.
    rng_photos : Generator
        Random stream for the measurement in the photos.
    rng_ortho : Generator
        Random stream for RANSAC in the orthophoto.

    Returns
    -------
    rule : dict or None
        The legs' measurement; None when the rule is not found.
    method : str or None
        ``"photos"``, ``"orthophoto"`` or None.
    note : str
        Why the photos gave no rule; empty when they did.
    """
    from kitegully.closerange.rule_photos import measure_rule_in_photos

    rule, why = measure_rule_in_photos(photos, images, sim, dem, grid, params.rule_paint_rgb, params.rule_strip_width_m,
                                       params.pole_height_m, params.outlier_tolerance_m, rng_photos)
    if rule is not None:
        log.info("folding rule measured in the photos: legs %.3f m, %.3f m (corner in %d photos, ends in %d, %d; %.2f px rms)",
                 rule["leg_a_m"], rule["leg_b_m"], rule["photos_corner"], rule["photos_a"], rule["photos_b"], rule["rms_px"])
        return rule, "photos", ""
    log.info("folding rule not measured in the photos (%s); trying the orthophoto", why)
    rule = measure_folding_rule(ortho, dem, grid, rng_ortho, params.rule_paint_rgb, params.rule_min_paint_fraction)
    return rule, (None if rule is None else "orthophoto"), why


@dataclass
class SphereGeoreference:
    """The similarity model → survey from the marker spheres found in the oriented photos.

    Attributes
    ----------
    sim : Similarity
        Model → site coordinates.
    found_all, found : list
        Triangulated sphere candidates, and those that passed :func:`verify_spheres` (one radius from
        every side), each ``(xyz, photo indices, ...)``.
    checks : list of dict
        The verification of each kept candidate (``radius``, ``height`` in model units).
    rows, perm : sequence of int
        Kept candidates paired with the survey (indices into ``found``) and their survey rows.
    res : ndarray (n, 3)
        Residuals of the paired spheres after the similarity (m).
    ids : list of str
        Survey ids (``gcp_id``).
    detections : list of (str, float, float)
        Every sphere detection (photo, u, v).
    centres : ndarray (n_photos, 3)
        Camera centres in the model.
    """

    sim: Similarity
    found_all: list
    found: list
    checks: list
    rows: Sequence[int]
    perm: Sequence[int]
    res: np.ndarray
    ids: list
    detections: list
    centres: np.ndarray


def georeference_on_spheres(photos: Sequence, images: Mapping[str, np.ndarray], sparse: np.ndarray, survey: pd.DataFrame,
                            params: "CloseRangeParams", source: str, scene: str) -> SphereGeoreference:
    """Detect the white marker spheres in the oriented photos, triangulate them and fit the similarity to the survey.

    Parameters
    ----------
    photos : sequence
        Oriented photos (:func:`read_oriented_photos`).
    images : mapping
        The photographs SfM saw, by name.
    sparse : ndarray (n, 3)
        Tie points of the model (the spheres stand above them).
    survey : DataFrame
        Surveyed sphere centres: ``gcp_id, x, y, z``.
    params : CloseRangeParams
    source, scene : str
        Named in messages and the log.

    Returns
    -------
    SphereGeoreference

    Notes
    -----
    Cost: the sphere detector over every photo, O(pixels); triangulation and pairing are small.
    """
    O, D, pid, alpha, det_rows = [], [], [], [], []
    for k, ph in enumerate(photos):
        det = detect_spheres(images[ph.name], ph.camera, params.spheres)
        if len(det):
            o, d = detection_rays(ph, det[["u_px", "v_px"]].to_numpy())
            O.append(o)
            D.append(d)
            pid += [k] * len(det)
            alpha += det["alpha_rad"].tolist()
            det_rows += [(ph.name, u, v) for u, v in det[["u_px", "v_px"]].to_numpy()]
    if not O:
        raise InputError(f"{source}: no white sphere was found in any of the {len(photos)} oriented photos")
    O, D, pid, alpha = np.concatenate(O), np.concatenate(D), np.array(pid), np.array(alpha)
    centres = np.array([p.centre for p in photos])
    ring = float(np.median(np.linalg.norm(centres - centres.mean(axis=0), axis=1)))
    tol = params.sphere_tolerance_m * ring / 5.0 if ring > 0 else params.sphere_tolerance_m
    # the model's scale is arbitrary: express the tolerance via the ring radius (~5 m at the walk's size)
    found_all = triangulate_spheres(O, D, pid, tol)
    checks_all = verify_spheres(found_all, O, alpha, sparse)
    found = [f for f, c in zip(found_all, checks_all) if c["sphere"]]
    checks = [c for c in checks_all if c["sphere"]]
    log.info("%s: %d sphere detections in %d photos, %d triangulated, %d with one radius from every side (radius spread <= 15 %%)",
             scene, len(O), len(photos), len(found_all), len(found))
    model_xyz = np.array([f[0] for f in found]).reshape(-1, 3)
    radii = np.array([c["radius"] for c in checks])
    sxyz = survey[["x", "y", "z"]].to_numpy(float)
    ids = survey["gcp_id"].astype(str).tolist()
    # plausibility: with the similarity the cameras stand at the pole's height above the
    # ground, here the plane through the surveyed spheres lowered by their radius (a scale or
    # an orientation from false candidates puts them metres too high, or under the ground)
    A = np.column_stack([sxyz[:, 0] - sxyz[:, 0].mean(), sxyz[:, 1] - sxyz[:, 1].mean(), np.ones(len(sxyz))])
    plane = np.linalg.lstsq(A, sxyz[:, 2], rcond=None)[0]

    def cameras_on_poles(sim_) -> bool:
        c = sim_.apply(centres)
        ground = plane[0] * (c[:, 0] - sxyz[:, 0].mean()) + plane[1] * (c[:, 1] - sxyz[:, 1].mean()) + plane[2] - params.sphere_radius_m
        h = float(np.median(c[:, 2] - ground))
        return 0.5 * params.pole_height_m <= h <= 2.0 * params.pole_height_m

    sim, rows, perm, res = match_markers(model_xyz, sxyz, ids, params.marker_budget_m, plausible=cameras_on_poles,
                                         radii=radii, radius_m=params.sphere_radius_m)
    return SphereGeoreference(sim, found_all, found, checks, rows, perm, res, ids, det_rows, centres)


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
    images = _read_photos(Path(work_dir) / "images", [p.name for p in photos])  # the prepared copies SfM saw
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
    keep = _near_median_surface(xyz, grid, params.outlier_cell_m, params.outlier_tolerance_m)
    log.info("%s: %d of %d dense points kept within %.2f m of the %.2f m median surface", scene, keep.sum(), len(keep),
             params.outlier_tolerance_m, params.outlier_cell_m)
    xyz, rgb = xyz[keep], rgb[keep]
    cams_w = sim.apply(centres)
    surf = grid_points(xyz, grid, rgb, params.trim, cams_w[:, :2], params.periphery)
    from kitegully.closerange.gridding import periphery_mask

    inside = periphery_mask(grid, cams_w[:, :2], params.periphery)
    holes_before = int((~np.isfinite(surf.dem) & inside).sum())
    dem, ortho, filled = _fill_holes(surf.dem, surf.ortho, inside, params.fill_holes_cells)
    from kitegully.seeds import rng_for

    rule_images = _original_photos(photo_dir, out["image_info"], images)
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


# --------------------------------------------------------------------------- closerange_summary
def failed_scene_record(scene: str, reason: str) -> dict:
    """The record of a scene that could not be georeferenced (``on_scene_failure: record``).

    Parameters
    ----------
    scene : scene name.
    reason : the InputError's one sentence.

    Returns
    -------
    dict
        ``{"scene", "status": "failed", "reason"}``; :func:`closerange_tables` lists it as a
        row without numbers and leaves it out of the means and the overall accuracy.
    """
    return {"scene": scene, "status": "failed", "reason": str(reason)}


def scene_succeeded(record: Mapping[str, Any]) -> bool:
    """Whether a ``closerange.json`` record is a georeferenced scene (records without ``status`` are)."""
    return record.get("status", "ok") == "ok"


@dataclass
class CloseRangeTables:
    """Products of :func:`closerange_tables`."""

    table1: pd.DataFrame
    accuracy: pd.DataFrame


def closerange_tables(
    records: Sequence[dict], confusion_sfm: Sequence[dict], confusion_direct: Sequence[dict],
    same_cells: Sequence[tuple[str, str, str]] = (),
) -> CloseRangeTables:
    """001 Table 1 per scene next to the paper's, and OBIA accuracy on the photogrammetric vs the direct orthophotos.

    ``records`` are the :func:`photogrammetric_orthophoto` records of all requested scenes,
    failed ones included (:func:`failed_scene_record`); the confusions are the obia stage's
    ``confusion.json`` records of the scenes that succeeded (photogrammetric and direct
    renders).  Both tables have ``status`` and ``reason`` columns: a failed scene is a row
    with its sentence and no numbers.  Each table ends with an ``all`` row over the scenes
    that succeeded (means for Table 1, the paper's too, over the same scenes; summed
    confusion matrices for the accuracy), whose ``status`` states the count ("8 of 10
    scenes").  ``same_cells`` gives per succeeded scene the paths of the direct and the
    photogrammetric classification and the truth mask: the direct classification is then
    also scored on the cells the photogrammetric one covers (``oa_direct_same_cells_pct``),
    which separates the effect of the crop from that of the SfM defects.

    Parameters
    ----------
    records : sequence of dict
        Scene records, failed ones included.
    confusion_sfm, confusion_direct : sequence of dict
        Confusion records of the succeeded scenes on the photogrammetric and the direct orthophotos.
    same_cells : sequence of (str, str, str)
        Paths of the direct classification, the photogrammetric classification and the truth mask, in the order
        of ``confusion_sfm``; empty to skip the same-cells score.

    Returns
    -------
    CloseRangeTables
        ``table1`` (Table 1 per scene) and ``accuracy`` (OBIA accuracy per scene), each with an ``all`` row.
    """
    from kitegully.io.raster import read_raster
    from kitegully.obia.accuracy import accuracies, confusion_matrix

    ok_recs = [r for r in records if scene_succeeded(r)]
    failed = [r for r in records if not scene_succeeded(r)]
    count = f"{len(ok_recs)} of {len(records)} scenes"
    failed_note = "" if not failed else "failed: " + ", ".join(r["scene"] for r in failed)
    t1 = pd.DataFrame([{
        "scene": r["scene"], "status": "ok", "reason": "", "images_used": r["images_used"], "images_aligned": r["images_aligned"],
        "marker_error_m": r["marker_error_m"], "spheres_measured": r["spheres_measured"],
        "scale_error_pct": np.nan if r["scale_error_pct"] is None else r["scale_error_pct"],
        "leg_a_m": np.nan if r["rule"] is None else r["rule"]["leg_a_m"],
        "leg_b_m": np.nan if r["rule"] is None else r["rule"]["leg_b_m"],
        "rule_method": r.get("rule_method") or ("" if r["rule"] is None else "orthophoto"),
        "sift": r.get("sift", "plain").split(" ")[0],
        "tie_points": r["tie_points"], "dense_points": r["dense_points"], "holes_pct": r["holes_pct"],
        "time_s": r["timings_s"]["total"],
    } if scene_succeeded(r) else {"scene": r["scene"], "status": "failed", "reason": r["reason"]} for r in records])
    if len(t1):
        t1 = t1.merge(PAPER_TABLE1, on="scene", how="left")
        ok = t1["status"] == "ok"
        mean = {c: t1.loc[ok, c].mean() for c in t1.columns if c not in ("scene", "status", "reason", "rule_method", "sift")}
        n_affine = int((t1.loc[ok, "sift"] == "affine").sum())
        t1.loc[len(t1)] = {"scene": "all", "status": count, "reason": failed_note, "sift": f"affine in {n_affine}", **mean}
        t1 = t1[[c for c in t1.columns if c != "reason"] + ["reason"]]  # the sentence last: the .md stays readable

    def acc_row(scene, conf):
        a = accuracies(np.asarray(conf))
        return {"oa": 100 * a["overall"], "ua_eroded": 100 * a["users"][1], "pa_eroded": 100 * a["producers"][1]}

    direct = {c["scene"]: c for c in confusion_direct}
    sfm = {c["scene"]: c for c in confusion_sfm}
    same = {}
    for (direct_path, sfm_path, truth_path), c in zip(same_cells, confusion_sfm):
        dc, _ = read_raster(direct_path)
        sc, _ = read_raster(sfm_path)
        tr, _ = read_raster(truth_path)
        same[c["scene"]] = confusion_matrix(dc, tr, valid=(sc != 255) & (dc != 255))
    rows, tot_s, tot_d, tot_x = [], np.zeros((2, 2)), np.zeros((2, 2)), np.zeros((2, 2))
    for r in records:
        if not scene_succeeded(r):
            rows.append({"scene": r["scene"], "status": "failed", "reason": r["reason"], "oa_paper_pct": PAPER_OA.get(r["scene"])})
            continue
        c, d = sfm[r["scene"]], direct[r["scene"]]
        tot_s += np.asarray(c["confusion"])
        tot_d += np.asarray(d["confusion"])
        x_ = acc_row(c["scene"], same[c["scene"]])["oa"] if c["scene"] in same else np.nan
        if c["scene"] in same:
            tot_x += same[c["scene"]]
        s_, d_ = acc_row(c["scene"], c["confusion"]), acc_row(c["scene"], d["confusion"])
        rows.append({"scene": c["scene"], "status": "ok", "reason": "",
                     "oa_sfm_pct": s_["oa"], "oa_direct_pct": d_["oa"], "oa_direct_same_cells_pct": x_,
                     "oa_paper_pct": PAPER_OA.get(c["scene"]),
                     "ua_eroded_sfm_pct": s_["ua_eroded"], "pa_eroded_sfm_pct": s_["pa_eroded"],
                     "ua_eroded_direct_pct": d_["ua_eroded"], "pa_eroded_direct_pct": d_["pa_eroded"],
                     "area_sfm_m2": c["area_auto_m2"], "area_ref_in_crop_m2": c["area_ref_m2"],
                     "area_direct_m2": d["area_auto_m2"], "area_ref_full_m2": d["area_ref_m2"]})
    if ok_recs:
        s_, d_ = acc_row("all", tot_s), acc_row("all", tot_d)
        rows.append({"scene": "all", "status": count, "reason": failed_note,
                     "oa_sfm_pct": s_["oa"], "oa_direct_pct": d_["oa"],
                     "oa_direct_same_cells_pct": acc_row("all", tot_x)["oa"] if same else np.nan, "oa_paper_pct": PAPER_OA["all"],
                     "ua_eroded_sfm_pct": s_["ua_eroded"], "pa_eroded_sfm_pct": s_["pa_eroded"],
                     "ua_eroded_direct_pct": d_["ua_eroded"], "pa_eroded_direct_pct": d_["pa_eroded"]})
    acc = pd.DataFrame(rows)
    if len(acc):
        acc = acc[[c for c in acc.columns if c != "reason"] + ["reason"]]
    for r in failed:
        log.info("%s: failed, not in the overall accuracy: %s", r["scene"], r["reason"])
    if ok_recs:
        log.info("OBIA: OA %.1f %% over %s on the photogrammetric orthophotos, %.1f %% on the direct renders of the same "
                 "scenes (paper 94.3 %% over 10)", acc["oa_sfm_pct"].iloc[-1], count, acc["oa_direct_pct"].iloc[-1])
    else:
        log.info("OBIA: no scene of %d was georeferenced; no overall accuracy", len(records))
    return CloseRangeTables(t1, acc)
