#!/usr/bin/env python
"""Why one camera of a twin's block is far off (issue 17, epoch 2's worst camera 0.54 m): per-camera evidence.

An evaluation script (reads the flight truth) on the stored outputs of a finished run, for one
epoch (``--epoch epoch2/`` or ``""``). Per registered image:

* ``n_obs``: its tie observations in the adjusted model; ``quadrants``: how many of the image's
  four quadrants hold them; ``extent_x``, ``extent_y``: their spread as a share of the image
  width / height (a narrow strip leaves a rotation and the translation across the strip
  correlated);
* ``hit_fraction`` (flight truth, ``flight/[epoch2/]image_stats.csv``): the share of the image
  that sees the surveyed (rendered) site; the rest sees nothing to tie;
* ``sd3_m``: first-order position SD of a resection from its own tie observations with the
  3-D points held fixed, σ = the block's tie RMS (px): σ²(JᵀJ)⁻¹ over the six pose
  parameters (a lower bound: point, intrinsic and datum errors left out, so the same for all
  cameras up to a common factor); ``rho_max``: the largest |correlation| between a position
  and an attitude parameter;
* ``d3_m`` (from ``georef/[epoch2/]twin_camera_errors.csv``), and ``d3_local_m``: the error
  after removing the block's mean error (the datum part every camera shares).

Writes ``benchmarks/out/georef_camera_diagnosis_<epoch>.md/.csv`` and prints the worst cameras
and the Spearman rank correlations of the error with each diagnostic.

    PYTHONPATH=src .venv/bin/python benchmarks/georef_camera_diagnosis.py --results results/kamech_twin --epoch epoch2/

Cost: a few seconds (one 6 × 6 normal matrix per image).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pycolmap
from scipy.spatial.transform import Rotation

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "src"))

from kitegully.io.tables import write_table  # noqa: E402


def resection_sd(rec: pycolmap.Reconstruction, im, sigma_px: float) -> tuple[float, float]:
    """(3-D position SD, max |ρ| position–attitude) of image ``im`` resected on its fixed tie points."""
    cam = rec.cameras[im.camera_id]
    pts = [p for p in im.points2D if p.has_point3D()]
    X = np.array([rec.points3D[p.point3D_id].xyz for p in pts])
    cfw = im.cam_from_world() if callable(im.cam_from_world) else im.cam_from_world
    R0 = cfw.rotation.matrix()
    C0 = -R0.T @ cfw.translation

    def proj(par):
        Rp = Rotation.from_rotvec(par[:3]).as_matrix() @ R0
        return cam.img_from_cam((X - par[3:]) @ Rp.T, False).ravel()

    p0 = np.concatenate([np.zeros(3), C0])
    f0 = proj(p0)
    J = np.empty((f0.size, 6))
    for k in range(6):
        dp = np.zeros(6)
        dp[k] = 1e-6 if k < 3 else 1e-3
        J[:, k] = (proj(p0 + dp) - f0) / dp[k]
    cov = sigma_px**2 * np.linalg.inv(J.T @ J)
    d = np.sqrt(np.diag(cov))
    rho = cov / np.outer(d, d)
    return float(np.sqrt(np.sum(d[3:] ** 2))), float(np.abs(rho[3:, :3]).max())


def diagnose(results: Path, epoch: str) -> pd.DataFrame:
    """The per-camera table described in the module docstring."""
    geo = results / "georef" / epoch
    rec = pycolmap.Reconstruction(str(geo / "model"))
    sigma = float(json.loads((geo / "summary.json").read_text())["tie_rms_px"])
    err = pd.read_csv(geo / "twin_camera_errors.csv")
    stats = pd.read_csv(results / "flight" / epoch / "image_stats.csv")
    rows = []
    for im in rec.images.values():
        cam = rec.cameras[im.camera_id]
        xy = np.array([p.xy for p in im.points2D if p.has_point3D()]).reshape(-1, 2)
        sd3, rho = resection_sd(rec, im, sigma)
        rows.append(dict(image=im.name.split("_", 1)[1] if "_" in im.name else im.name, n_obs=len(xy),
                         quadrants=len({(int(2 * x / cam.width), int(2 * y / cam.height)) for x, y in xy}),
                         extent_x=float(np.ptp(xy[:, 0]) / cam.width) if len(xy) else 0.0,
                         extent_y=float(np.ptp(xy[:, 1]) / cam.height) if len(xy) else 0.0, sd3_m=sd3, rho_max=rho))
    df = pd.DataFrame(rows).merge(stats[["image", "hit_fraction"]], on="image").merge(err, on="image")
    mean = df[["dx_m", "dy_m", "dz_m"]].mean()
    df["d3_local_m"] = np.sqrt(((df[["dx_m", "dy_m", "dz_m"]] - mean) ** 2).sum(axis=1))
    df["ratio_error_sd"] = df["d3_m"] / df["sd3_m"]
    return df.sort_values("d3_m", ascending=False).reset_index(drop=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--results", default="results/kamech_twin", type=Path)
    ap.add_argument("--epoch", default="epoch2/", help='"epoch2/" or "" (epoch 1)')
    a = ap.parse_args()
    df = diagnose(a.results, a.epoch)
    name = a.epoch.strip("/") or "epoch1"
    out = REPO / "benchmarks" / "out"
    out.mkdir(parents=True, exist_ok=True)
    write_table(df, out / f"georef_camera_diagnosis_{name}.csv")
    print(df.head(8).round(3).to_string())
    for col in ("n_obs", "hit_fraction", "extent_x", "sd3_m", "quadrants"):
        print(f"Spearman(d3_m, {col}) = {df[['d3_m', col]].corr('spearman').iloc[0, 1]:+.2f}")
    print("block mean error (m):", df[["dx_m", "dy_m", "dz_m"]].mean().round(3).to_dict(),
          "median error/resection-SD ratio:", round(float(df["ratio_error_sd"].median()), 2))


if __name__ == "__main__":
    main()
