"""Re-render only the folding rule's neighbourhood of the stored close-range photos with the twin's current rule (issue 20).

The session-10 twin draws the rule as a rigid L resting on the ground
(:func:`kitegully.twin.polewalk.composite_rule`) where the session-9 photos had it painted
onto the grass texture (draped over the tussocks).  Rendering all 324 photos again and
rerunning the SfM takes a full ``make closerange``; this benchmark instead replaces, in each
stored photo, the box that holds both the old painted rule and the new rigid one (plus a
margin) with a fresh render of that box: a camera cropped to the box (principal point
shifted), the terrain without paint, the spheres and the rigid rule composited, then the
photographic effects drawn from the photo's own random stream on a full-size frame (same
exposure scatter, vignetting and noise as the stored photo), pasted, and the photo JPEG
encoded at quality 95, 4:4:4 as ``closerange_photos`` writes it.  Outside the box the stored
photo is kept, so the stored COLMAP model (built from photos that differ only in the rule's
pixels) stays the cameras.  Pixels of the box away from both rules are compared with the
stored photo as a check that the re-render reproduces it.

Twin side (it reads the scenes' truth). Usage (repository root, PYTHONPATH=src):
    python benchmarks/closerange_rule_rerender.py --out results/kamech_twin/closerange_rule/photos [--scenes ...]
"""

from __future__ import annotations

import argparse
import io
import json
import sys
import time
from pathlib import Path

import cv2
import numpy as np
from PIL import Image

sys.path.insert(0, str(Path(__file__).resolve().parent))
from closerange_rule_scene import REPO, site_config  # noqa: E402

from kitegully.closerange.stage import scene_walk  # noqa: E402
from kitegully.seeds import rng_for  # noqa: E402
from kitegully.twin.camera import Camera  # noqa: E402
from kitegully.twin.polewalk import RULE_WIDTH_M, composite_rule, composite_spheres  # noqa: E402
from kitegully.twin.render import Photographic, photograph, render_reflectance, surface_height  # noqa: E402

SCENES = [f"scene_{i:02d}" for i in (1, 2, 3, 4, 5, 7, 8, 9, 10)]
#: [I] margin (px) around both rules: the paint's blur (~1 px) and JPEG's 8 px blocks
MARGIN_PX = 12


def rule_samples(rule: np.ndarray, render) -> np.ndarray:
    """Points on a rule every cm along both legs, at its centre line and both edges."""
    a, c, b = rule
    s = np.arange(-0.01, 1.0001, 0.01)
    out = []
    for e, other in ((a, b), (b, a)):
        u, v = (e - c), (other - c)
        for q in (-0.5 * RULE_WIDTH_M, 0.0, 0.5 * RULE_WIDTH_M):
            out.append(c[None] + s[:, None] * u[None] + q * v[None])
    return np.vstack(out)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--results", default="/work/wt/closerange9/results/kamech_twin")
    ap.add_argument("--site", default="kamech_twin")
    ap.add_argument("--scenes", nargs="*", default=SCENES)
    ap.add_argument("--out", default=str(REPO / "results" / "kamech_twin" / "closerange_rule" / "photos"))
    a = ap.parse_args()
    cfg = site_config(a.site)
    cr = cfg["closerange"]
    res = Path(a.results)
    report = {}
    for scene in a.scenes:
        t0 = time.perf_counter()
        od = res / "obia" / "scenes" / scene
        meta = json.loads((od / "truth" / "scene.json").read_text())
        import pandas as pd

        ps, walk, poses = scene_walk(str(od / "orthophoto.tif"), str(od / "dem.tif"), str(od / "truth" / "markers.tif"),
                                     str(od / "truth" / "eroded.tif"), meta, pd.read_csv(od / "markers.csv"), cr["walk"],
                                     float(cfg["obia"]["scenes"]["marker_radius_m"]), True, cfg["seed"], scene)
        stored = json.loads((res / "closerange" / "scenes" / scene / "truth" / "walk.json").read_text())
        old_rule = np.array(stored["rule"])
        assert np.abs(ps.rule[1, :2] - old_rule[1, :2]).max() < 1e-9, "rule placed elsewhere"
        assert np.abs(np.array([p.C for p in poses]) - np.array(stored["camera_centres"])).max() < 1e-9
        # the stored photos' rule: painted on the texture, i.e. the stored rule's plan position at the surface's height
        old_pts = rule_samples(old_rule, ps.render)
        old_pts[:, 2] = surface_height(ps.render, old_pts[:, 0], old_pts[:, 1])
        new_pts = rule_samples(ps.rule, ps.render)
        cam = walk.camera()
        fx = Photographic(exposure_gain=1.0, exposure_ev_sd=0.1, vignetting=0.2, gamma=1.0,
                          read_noise_dn=1.0, shot_noise_dn2_per_dn=0.05, exposure_time_s=0.002)
        rng = rng_for(cfg["seed"], "closerange", scene, "photos")
        out = Path(a.out) / scene
        out.mkdir(parents=True, exist_ok=True)
        diffs, boxes = [], []
        for i, pose in enumerate(poses):
            name = f"IMG_{i:04d}.JPG"
            photo = cv2.cvtColor(cv2.imread(str(res / "closerange" / "scenes" / scene / "photos" / name)), cv2.COLOR_BGR2RGB)
            uv = np.vstack([cam.project(old_pts, pose), cam.project(new_pts, pose)])
            uv = uv[np.isfinite(uv).all(axis=1)]
            inside = cam.in_image(uv, -MARGIN_PX)
            full = np.zeros((cam.height, cam.width, 3), np.float32)
            box = None
            if inside.any():
                u0, v0 = np.maximum(np.floor(uv[inside].min(axis=0)).astype(int) - MARGIN_PX, 0)
                u1, v1 = np.minimum(np.ceil(uv[inside].max(axis=0)).astype(int) + MARGIN_PX, [cam.width - 1, cam.height - 1])
                box = (int(u0), int(v0), int(u1), int(v1))
                sub = Camera(width=u1 - u0 + 1, height=v1 - v0 + 1, f=cam.f, cx=cam.cx - u0, cy=cam.cy - v0)
                refl, depth = render_reflectance(ps.render, sub, pose, (0, 1, 2), walk.supersampling, (0.55, 0.65, 0.8))
                composite_spheres(refl, depth, sub, pose, ps.spheres, ps.sphere_radius_m, ps.sphere_dn, ps.sun, ps.diffuse_fraction)
                composite_rule(refl, depth, sub, pose, ps.rule, ps.sun, ps.diffuse_fraction)
                full[v0:v1 + 1, u0:u1 + 1] = refl
            img, _ = photograph(full, cam, fx, rng)  # the photo's own stream: same exposure and noise
            if box is not None:
                u0, v0, u1, v1 = box
                new = img[v0:v1 + 1, u0:u1 + 1]
                # check: pixels of the box at least 6 px from both rules reproduce the stored photo
                near = np.zeros(new.shape[:2], np.uint8)
                for q in uv[inside]:
                    cv2.circle(near, (int(round(q[0] - u0)), int(round(q[1] - v0))), 6, 1, -1)
                far = near == 0
                if far.any():
                    diffs.append(float(np.sqrt(np.mean((new[far].astype(float) - photo[v0:v1 + 1, u0:u1 + 1][far].astype(float)) ** 2))))
                photo[v0:v1 + 1, u0:u1 + 1] = new
                boxes.append((u1 - u0 + 1) * (v1 - v0 + 1))
            buf = io.BytesIO()
            Image.fromarray(photo).save(buf, format="JPEG", quality=95, subsampling=0)
            (out / name).write_bytes(buf.getvalue())
        report[scene] = {"rms_dn_off_rule": float(np.median(diffs)) if diffs else None, "box_px_median": float(np.median(boxes)),
                         "seconds": time.perf_counter() - t0, "rule": ps.rule.tolist()}
        print(scene, report[scene], flush=True)
        (out / "rule_truth.json").write_text(json.dumps({"rule": ps.rule.tolist()}))
    (Path(a.out) / "rerender_report.json").write_text(json.dumps(report, indent=1))


if __name__ == "__main__":
    main()
