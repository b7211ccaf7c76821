#!/usr/bin/env python
"""Why the default twin's epoch-2 block sat ~0.1 m high (issue 17): the evidence, reproducible.

An evaluation script (reads the twin's truth). On the SfM model and GCP file of a finished
run it measures, for one epoch (``--epoch epoch2/`` or ``""``):

1. **twin consistency**: the SfM tie observations and the GCP clicks intersected with the
   *true* poses and camera: ties against the true DSM (median), clicks against the true
   target positions (per target), true pixels against the targets (must be 0);
2. **adjustment variants** (one GCP bundle each, no leave-one-out): as configured; focal
   length fixed at its true value (the f / flying-height correlation); camera RMSE and the
   mean camera height error against the flight truth, and the re-triangulated tie points
   against the true DSM (median and a quadratic-in-plan fit: offset at the site centre);
3. **click draws** (``--draws N``): the targets digitised again from their true pixels with
   the site's click noise, the adjustment repeated: the spread of the block's height datum
   that click noise alone produces.

    PYTHONPATH=src .venv/bin/python benchmarks/epoch2_datum_diagnosis.py --epoch epoch2/ --draws 8

Cost: about 10 s per adjustment on 2 cores (idle machine); prints one line per case.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pycolmap
import rasterio
import yaml

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "src"))

from kitegully.georef.control import solve  # noqa: E402
from kitegully.georef.observations import collect_observations, triangulate_gcps  # noqa: E402
from kitegully.georef.quality import select_gcps  # noqa: E402
from kitegully.georef.gcp_io import read_gcps  # noqa: E402
from kitegully.georef.geometry import camera_centres  # noqa: E402
from kitegully.georef.model import block_from_reconstruction, retriangulate_all  # noqa: E402
from kitegully.georef.stage import GeorefParams  # noqa: E402
from kitegully.seeds import rng_for  # noqa: E402
from kitegully.sfm.stage import load_image_infos  # noqa: E402
from kitegully.twin.camera import Camera  # noqa: E402
from kitegully.twin.flight import pose_from_row  # noqa: E402
from kitegully.twin.flight_gcps import digitise, read_odm_gcp_list, write_odm_gcp_list  # noqa: E402


def _rays(cam: dict, pose, xy: np.ndarray) -> np.ndarray:
    """Unit world directions of pixels ``xy`` (pixel centres at integers) through a true pose."""
    f, cx, cy, k1, k2 = cam["colmap_params"]
    u, v = (xy[:, 0] - cx) / f, (xy[:, 1] - cy) / f
    x, y = u.copy(), v.copy()
    for _ in range(30):
        r2 = x * x + y * y
        d = 1 + k1 * r2 + k2 * r2 * r2
        x, y = u / d, v / d
    d = np.c_[x, y, np.ones_like(x)] @ pose.R
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def _intersect(C: np.ndarray, D: np.ndarray) -> np.ndarray:
    A, b = np.zeros((3, 3)), np.zeros(3)
    for c, d in zip(C, D):
        M = np.eye(3) - np.outer(d, d)
        A += M
        b += M @ c
    return np.linalg.solve(A, b)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--epoch", default="epoch2/")
    ap.add_argument("--draws", type=int, default=0)
    ap.add_argument("--site", default=str(REPO / "config" / "sites" / "kamech_twin.yaml"))
    ap.add_argument("--results", default=str(REPO / "results" / "kamech_twin"))
    a = ap.parse_args()
    R, pre = Path(a.results), a.epoch
    cfg = yaml.safe_load(Path(a.site).read_text())
    P = GeorefParams.from_config(cfg["georef"])
    rec = pycolmap.Reconstruction(str(R / "sfm" / pre / "model"))
    infos = load_image_infos(R / "sfm" / pre / "image_info.json")
    poses = pd.read_csv(R / "flight" / pre / "truth" / "poses.csv").set_index("image")
    cam = json.loads((R / "flight" / pre / "truth" / "camera.json").read_text())
    dsm = rasterio.open(R / "twin" / pre / "truth" / "dsm.tif")
    targets = pd.read_csv(R / "twin" / pre / "truth" / "targets.csv").set_index("gcp_id")
    sfm_to_name = {i.sfm_name: i.name for i in infos}

    # 1. the twin is consistent: tie observations and clicks through the true geometry
    true_pose = {iid: pose_from_row(poses.loc[sfm_to_name[im.name]].to_dict()) for iid, im in rec.images.items()}
    pts = list(rec.points3D.values())
    sel = np.random.default_rng(0).choice(len(pts), min(5000, len(pts)), replace=False)
    X = []
    for j in sel:
        el = pts[j].track.elements
        C = np.array([true_pose[e.image_id].C for e in el])
        D = np.vstack([_rays(cam, true_pose[e.image_id], rec.images[e.image_id].points2D[e.point2D_idx].xy[None] - 0.5) for e in el])
        X.append(_intersect(C, D))
    X = np.array(X)
    e = X[:, 2] - np.array([v[0] for v in dsm.sample(zip(X[:, 0], X[:, 1]))])
    print(f"ties through the true poses - true DSM: median {np.nanmedian(e):+.3f} m (n {np.isfinite(e).sum()})")
    crs, clicks = read_odm_gcp_list(R / "flight" / pre / "observed" / "gcp_list.txt")
    dzs = []
    for g, grp in clicks.groupby("gcp_id"):
        ps = [pose_from_row(poses.loc[i].to_dict()) for i in grp["image"]]
        D = np.vstack([_rays(cam, p, np.array([[x, y]])) for p, x, y in zip(ps, grp["im_x_px"], grp["im_y_px"])])
        dz = _intersect(np.array([p.C for p in ps]), D)[2] - targets.loc[g, "z"]
        dzs.append(dz)
        print(f"  {g}: {len(grp)} clicks through the true poses, height {dz:+.3f} m from the true target")
    print(f"clicks through the true poses: mean height error {np.mean(dzs):+.3f} m over {len(dzs)} targets")

    # 2. and 3. the adjustment: variants and click draws
    seed = int(rng_for(cfg["seed"], "georef").integers(2**31 - 1))
    block, index = block_from_reconstruction(rec, P.max_tie_points, seed, P.tie_grid)
    rows = {n.split("/")[-1]: k for k, n in enumerate(index.image_names)}
    names = [sfm_to_name[n] for n in index.image_names]
    survey = (clicks.groupby("gcp_id")[["geo_x", "geo_y", "geo_z"]].first()
              .rename(columns={"geo_x": "x", "geo_y": "y", "geo_z": "z"}).reset_index())

    def run(gcp_file: Path, label: str, settings=P.bundle, intr_f: float | None = None) -> float:
        gcps = read_gcps(gcp_file, cfg["site"]["crs"], "odm")
        obs = collect_observations(gcps, infos, rows, P.gcp_pixel_frame, cfg["sfm"]["image_frame"], P.gcp_pixel_scale,
                                   P.qa.coords_tolerance_m, P.gcp_pixel_offset_px)
        xyz = np.array([o.gcp.xyz for o in obs])
        off = np.round(np.median(xyz, 0) / 100) * 100
        off[2] = 0
        b = block.copy()
        if intr_f is not None:
            b.intr[:, 0] = intr_f
        Xm, rp = triangulate_gcps(b, obs)
        use = select_gcps(obs, Xm, rp, xyz - off, P.qa, P.method)
        local, _, _ = solve(b, obs, xyz - off, Xm, use, P.method, settings)
        d = camera_centres(local.rv, local.t) - (poses.loc[names, ["x_m", "y_m", "z_m"]].to_numpy() - off)
        Xt, _ = retriangulate_all(local, index)
        Xt = Xt[np.all(np.isfinite(Xt), 1)]
        et = Xt[:, 2] - np.array([v[0] for v in dsm.sample(zip(Xt[:, 0] + off[0], Xt[:, 1] + off[1]))])
        ok = np.isfinite(et) & (np.abs(et - np.nanmedian(et)) < 0.5)
        x, y = (Xt[ok, 0] + off[0] - 579000) / 1e3, (Xt[ok, 1] + off[1] - 4081400) / 1e3
        c, *_ = np.linalg.lstsq(np.c_[np.ones_like(x), x, y, x * x, y * y, x * y], et[ok], rcond=None)
        print(f"{label:28s} f {local.intr[0, 0]:.2f} px | cameras: RMSE {np.sqrt((d ** 2).sum(1).mean()):.3f} m, max "
              f"{np.sqrt((d ** 2).sum(1)).max():.3f} m, mean height error {d[:, 2].mean():+.3f} m | ties - true DSM: median "
              f"{np.median(et[ok]):+.3f} m, at the site centre {c[0]:+.3f} m", flush=True)
        return float(c[0])

    run_list = R / "flight" / pre / "observed" / "gcp_list.txt"
    run(run_list, "as configured")
    run(run_list, "f fixed at the true value", dataclasses.replace(P.bundle, refine=tuple(r for r in P.bundle.refine if r != "f")),
        intr_f=cam["f"])
    if a.draws:
        truth_px = pd.read_csv(R / "flight" / pre / "truth" / "gcp_pixels.csv")
        camera = Camera.read_json(R / "flight" / pre / "truth" / "camera.json")
        g = cfg["flight"]["gcps"]
        centre = []
        tmp = REPO / "results" / "benchmarks" / "epoch2_datum_draws"
        tmp.mkdir(parents=True, exist_ok=True)
        for s in range(1, a.draws + 1):
            path = tmp / f"gcp_list_{s}.txt"
            write_odm_gcp_list(path, crs, digitise(truth_px, camera, np.random.default_rng(s), g["click_sigma_px"],
                                                   g["max_images_per_target"]), survey)
            centre.append(run(path, f"click draw {s}"))
        print(f"block height at the site centre over {a.draws} click draws: mean {np.mean(centre):+.3f} m, "
              f"SD {np.std(centre, ddof=1):.3f} m")


if __name__ == "__main__":
    main()
