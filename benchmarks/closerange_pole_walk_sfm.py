"""Pole-camera walk of one close-range scene -> photos -> the sfm stage's ``reconstruct_model``.

Measures (issue 20, library check): rendering time per photo, sphere detections and their
error against the true projections, and how many photos SfM registers and how long it takes.

Usage (from the repository root, PYTHONPATH=src):
    python benchmarks/closerange_pole_walk_sfm.py [--site tiny_twin] [--scene 0] [--images 24] [--out /tmp/cr]
"""

from __future__ import annotations

import argparse
import json
import time
from datetime import datetime, timedelta
from pathlib import Path

import numpy as np
import yaml

from kitegully.closerange.spheres import detect_spheres
from kitegully.seeds import rng_for
from kitegully.sfm.stage import SfmParams, reconstruct_model
from kitegully.twin.closerange import generate_scene, scene_names, scene_origin
from kitegully.twin.exif import exif_bytes, write_jpeg
from kitegully.twin.polewalk import PoleWalk, photograph_walk, prepare_pole_scene, project_spheres, walk_poses

REPO = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--site", default="tiny_twin")
    ap.add_argument("--scene", type=int, default=0)
    ap.add_argument("--images", type=int, default=24)
    ap.add_argument("--features", type=int, default=4096)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--out", default="/tmp/closerange_walk")
    a = ap.parse_args()
    cfg = yaml.safe_load((REPO / "config" / "sites" / f"{a.site}.yaml").read_text())
    p = cfg["obia"]["scenes"]
    name = scene_names(len(p["list"]))[a.scene]
    out = Path(a.out)
    t0 = time.perf_counter()
    sc = generate_scene(name, p, p["list"][a.scene], cfg["seed"], cfg["site"]["crs"], scene_origin(a.scene, p))
    ps = prepare_pole_scene(sc, float(p["marker_radius_m"]), a.scene != 5, rng_for(cfg["seed"], "closerange", name, "rule"))
    walk = PoleWalk(n_images=a.images)
    poses = walk_poses(ps, walk, rng_for(cfg["seed"], "closerange", name, "walk"))
    cam = walk.camera()
    t1 = time.perf_counter()
    errs, n_det = [], 0
    when = datetime(2015, 7, 14, 10, 0, 0)
    for i, img in photograph_walk(ps, walk, poses, rng_for(cfg["seed"], "closerange", name, "photos")):
        write_jpeg(out / "photos" / f"IMG_{i:04d}.JPG", img, exif_bytes(cam, when + timedelta(seconds=5 * i)), 95)
        truth = project_spheres(cam, poses[i], ps.spheres)
        det = detect_spheres(img, cam)
        n_det += len(det)
        errs += [float(np.nanmin(np.hypot(truth[:, 0] - u, truth[:, 1] - v))) for u, v in det[["u_px", "v_px"]].to_numpy()]
    t2 = time.perf_counter()
    s = dict(cfg["sfm"], max_num_features=a.features, first_octave=0, threads=a.threads)
    s["matching"] = dict(s["matching"], camera_log=None, method="exhaustive")
    summary = reconstruct_model(out / "photos", out / "work", out / "model", out / "summary.json", out / "images.csv",
                                out / "image_info.json", SfmParams.from_config(s), cfg["seed"], a.threads)
    t3 = time.perf_counter()
    e = np.array(errs)
    res = {
        "scene": name, "scene_m": sc.grid.width * sc.grid.cell, "patch_reach_m": ps.patch_reach_m,
        "images": a.images, "image_px": [cam.width, cam.height], "scene_prep_s": t1 - t0,
        "render_s_per_image": (t2 - t1) / a.images, "sphere_detections": n_det,
        "sphere_error_px_median": float(np.median(e)) if e.size else None,
        "sphere_error_px_max": float(e.max()) if e.size else None,
        "sfm_registered": summary["n_registered"], "sfm_points3d": summary["n_points3d"],
        "sfm_reprojection_px": summary["mean_reprojection_error_px"], "sfm_s": t3 - t2,
    }
    print(json.dumps(res, indent=1))


if __name__ == "__main__":
    main()
