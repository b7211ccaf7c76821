"""View geometry of each close-range scene's pole walk: where plain SIFT's affine limit falls (issue 20).

For every OBIA scene of a twin site, the walk that ``closerange_photos`` renders is rebuilt
(same random streams, no rendering) and the geometry that decides whether plain SIFT can
link neighbouring photos is printed:

* the grazing angle γ of each photo's optical axis to the scene's ground plane (DEM
  least-squares plane) and the view tilt ``t = 1/sin γ``;
* the azimuth step Δφ between neighbouring photos around the patch centre;
* the azimuth ``Δφ*`` at which two views of tilt ``t`` reach SIFT's transition-tilt limit
  τ = 2 (``τ + 1/τ = 2 + (t − 1/t)² sin²Δφ``, so ``sin Δφ* = √0.5 / (t − 1/t)``), with
  the median ``t`` of the two photos of each step, and the steps beyond it.

Twin side (reads the scenes' truth masks, as the photos rule does). A few seconds per scene.

Usage (repository root, PYTHONPATH=src; needs results/<site>/obia/scenes/):
    python benchmarks/closerange_walk_geometry.py [--site kamech_twin] [--n-images 36]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pandas as pd
import yaml

from kitegully.closerange.stage import scene_walk

REPO = Path(__file__).resolve().parents[1]


def limit_deg(t: np.ndarray) -> np.ndarray:
    """Azimuth difference (deg) at which two views of tilt t reach transition tilt 2."""
    s = np.sqrt(0.5) / np.maximum(t - 1.0 / t, 1e-9)
    return np.degrees(np.arcsin(np.clip(s, 0.0, 1.0)))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--site", default="kamech_twin")
    ap.add_argument("--n-images", type=int, default=None, help="override closerange.walk.n_images")
    a = ap.parse_args()
    cfg = yaml.safe_load((REPO / "config" / "sites" / f"{a.site}.yaml").read_text())
    cr = cfg["closerange"]
    walk_cfg = dict(cr["walk"], **({"n_images": a.n_images} if a.n_images else {}))
    root = REPO / "results" / a.site / "obia" / "scenes"
    rows = []
    for d in sorted(root.glob("scene_*")):
        scene = d.name
        meta = json.loads((d / "truth" / "scene.json").read_text())
        ps, walk, poses = scene_walk(str(d / "orthophoto.tif"), str(d / "dem.tif"), str(d / "truth" / "markers.tif"),
                                     str(d / "truth" / "eroded.tif"), meta, pd.read_csv(d / "markers.csv"), walk_cfg,
                                     float(cfg["obia"]["scenes"]["marker_radius_m"]), scene not in cr["scenes_without_rule"],
                                     cfg["seed"], scene)
        r = ps.render
        dem = r.dsm[::5, ::5].astype(np.float64)
        rr, cc = np.nonzero(np.isfinite(dem))
        X = np.column_stack([r.x0 + (cc * 5 + 0.5) * r.cell, r.y0 - (rr * 5 + 0.5) * r.cell, np.ones(rr.size)])
        a_, b_, _ = np.linalg.lstsq(X, dem[rr, cc], rcond=None)[0]
        n = np.array([-a_, -b_, 1.0]) / np.linalg.norm([-a_, -b_, 1.0])
        axis = np.array([p.R[2] for p in poses])  # optical axes (world)
        gamma = np.degrees(np.arcsin(np.abs(axis @ n)))
        t = 1.0 / np.sin(np.radians(gamma))
        C = np.array([p.C for p in poses])
        az = np.degrees(np.arctan2(C[:, 1] - ps.patch_centre[1], C[:, 0] - ps.patch_centre[0]))
        order = np.argsort(az)
        step = np.diff(np.concatenate([az[order], az[order[:1]] + 360.0]))
        t_pair = np.maximum(t[order], np.roll(t[order], -1))  # the steeper view of each neighbouring pair
        lim = limit_deg(t_pair)
        ring = np.hypot(C[:, 0] - ps.patch_centre[0], C[:, 1] - ps.patch_centre[1])
        rows.append({
            "scene": scene, "slope_deg": float(np.degrees(np.arctan(np.hypot(a_, b_)))),
            "ring_m": float(np.median(ring)), "gamma_median_deg": float(np.median(gamma)),
            "t_median": float(np.median(t)), "limit_median_deg": float(np.median(lim)),
            "step_median_deg": float(np.median(step)), "step_max_deg": float(step.max()),
            "steps_beyond_limit": int((step > lim).sum()), "n_images": len(poses),
        })
        print(json.dumps(rows[-1]), flush=True)
    print(pd.DataFrame(rows).to_string(index=False, float_format=lambda v: f"{v:.1f}"))


if __name__ == "__main__":
    main()
