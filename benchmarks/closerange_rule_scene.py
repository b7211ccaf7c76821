"""Load one stored close-range scene for re-measuring its folding rule (issue 20), without rerunning the SfM.

What ``closerange_sfm`` had when it measured the rule: the oriented photos (COLMAP model),
the photographer's originals, the sphere similarity (re-derived from the stored model and
prepared copies exactly as the stage does: same detection, grouping, pairing), the DEM
and its grid.  Twin side (evaluation only): the rebuilt walk (true poses, ideal camera)
and the painted rule.  The similarity is cached as JSON next to the outputs.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import yaml

from kitegully.closerange import CloseRangeParams
from kitegully.closerange.model import read_oriented_photos
from kitegully.closerange.markers import georeference_on_spheres
from kitegully.closerange.photos import original_photos, read_photos
from kitegully.closerange.stage import scene_walk
from kitegully.georef.similarity import Similarity
from kitegully.io.raster import read_raster

REPO = Path(__file__).resolve().parents[1]


def site_config(site: str) -> dict:
    return yaml.safe_load((REPO / "config" / "sites" / f"{site}.yaml").read_text())


def stage_params(cfg: dict) -> CloseRangeParams:
    """The params ``closerange_sfm`` builds (workflow/rules/closerange.smk)."""
    cr = cfg["closerange"]
    keys = ("spheres", "sfm_max_num_features", "sfm_affine_features", "sphere_tolerance_m", "marker_budget_m", "dense", "trim",
            "periphery", "fill_holes_cells", "outlier_cell_m", "outlier_tolerance_m", "min_dense_points", "rule_paint_rgb",
            "rule_min_paint_fraction", "rule_strip_width_m", "on_scene_failure")
    return CloseRangeParams.from_config(dict({k: cr[k] for k in keys if k in cr}, pole_height_m=cr["walk"].get("pole_height_m", 3.0),
                                             sphere_radius_m=cfg["obia"]["scenes"]["marker_radius_m"]))


@dataclass
class StoredScene:
    scene: str
    photos: list
    images: dict
    sim: Similarity
    dem: np.ndarray
    grid: object
    params: CloseRangeParams
    seed: int
    record: dict
    truth_rule: np.ndarray | None = None  # (3, 3) A, corner, B (the twin's rigid rule)
    poses: list | None = None
    camera: object = None
    render: object = None


def load_scene(results: Path, scene: str, cache: Path, site: str = "kamech_twin", truth: bool = True,
               photo_dir: Path | None = None) -> StoredScene:
    """Everything the rule measurement of ``scene`` needs, from ``results/<site>`` (read only).

    ``photo_dir``: the photographer's files from elsewhere (re-rendered rule,
    ``closerange_rule_rerender.py``); the truth rule is then its ``rule_truth.json`` (rigid
    rule: the photographed points), and the stored truth is checked in plan only.
    """
    cfg = site_config(site)
    params = stage_params(cfg)
    d = results / "closerange" / "scenes" / scene
    od = results / "obia" / "scenes" / scene
    photos, sparse = read_oriented_photos(d / "model")
    cache.mkdir(parents=True, exist_ok=True)
    cf = cache / f"{scene}_similarity.json"
    prepared = None
    if cf.exists():
        s = json.loads(cf.read_text())
        sim = Similarity(s["scale"], np.array(s["rotation"]), np.array(s["translation_m"]))
    else:
        prepared = read_photos(d / "sfm_work" / "images", [p.name for p in photos])
        # the stage's own sphere georeferencing (closerange.markers.georeference_on_spheres)
        sim = georeference_on_spheres(photos, prepared, sparse, pd.read_csv(od / "markers.csv"), params, str(d), scene).sim
        cf.write_text(json.dumps(sim.as_dict()))
    if prepared is None:
        prepared = {p.name: None for p in photos}
    images = original_photos(photo_dir or (d / "photos"), d / "image_info.json", {k: v if v is not None else _shape_probe(d, k) for k, v in prepared.items()})
    dem, grid = read_raster(d / "dem.tif")
    dem = np.asarray(dem, float).squeeze()
    record = json.loads((d / "closerange.json").read_text())
    st = StoredScene(scene, photos, images, sim, dem, grid, params, int(cfg["seed"]), record)
    if truth:
        meta = json.loads((od / "truth" / "scene.json").read_text())
        cr = cfg["closerange"]
        ps, walk, poses = scene_walk(str(od / "orthophoto.tif"), str(od / "dem.tif"), str(od / "truth" / "markers.tif"),
                                     str(od / "truth" / "eroded.tif"), meta, pd.read_csv(od / "markers.csv"), cr["walk"],
                                     float(cfg["obia"]["scenes"]["marker_radius_m"]), scene not in cr["scenes_without_rule"],
                                     cfg["seed"], scene)
        st.poses, st.camera, st.render = poses, walk.camera(), ps.render
        stored = json.loads((d / "truth" / "walk.json").read_text())
        # the stored photos' rule is the stored truth (the rule of the code that rendered them);
        # the re-rendered photos' rule is the current twin's (same corner, ends moved by its resting plane)
        st.truth_rule = np.array(stored["rule"]) if photo_dir is None else \
            np.array(json.loads((photo_dir / "rule_truth.json").read_text())["rule"])
        if np.abs(st.truth_rule[1, :2] - np.array(stored["rule"])[1, :2]).max() > 1e-6:
            raise RuntimeError(f"{scene}: the rule's corner differs from the stored truth")
        if np.abs(np.array([p.C for p in poses]) - np.array(stored["camera_centres"])).max() > 1e-6:
            raise RuntimeError(f"{scene}: the rebuilt walk's cameras differ from the stored truth")
    return st


def _shape_probe(d: Path, sfm_name: str) -> np.ndarray:
    """A zero image of the prepared copy's shape (the originals replace it when they are the SfM's grid)."""
    import cv2

    img = cv2.imread(str(d / "sfm_work" / "images" / sfm_name), cv2.IMREAD_COLOR)
    return np.zeros_like(img)
