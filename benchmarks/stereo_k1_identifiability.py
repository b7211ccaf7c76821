"""Stereo (paper 003): is K1 identifiable to 10 % with the 32-point field? (README "Plot-scale stereo", Calibration)

For ``--seeds`` draws (field error 0.2 mm, targets 0.1 px) and both cameras, the stage's weighted-control
bundle is run on the paper's 6 shifted images + 8 convergent rolled ones, with the convergent images aimed
at the field's centre (the stage) and with the field turned into the frame corners
(``convergent_poses(corner_fraction=0.5)``). Reported per design and camera: the radial reach of the
targets, K1's error and standard error, corr(K1, K2), the corner displacement's error and standard
error, and the f error.

Usage: PYTHONPATH=src .venv/bin/python benchmarks/stereo_k1_identifiability.py [--seeds 8]
Writes benchmarks/out/stereo_k1_identifiability.md. One core, ≈ 10 s per calibration (2 × 2 × seeds).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from kitegully.seeds import rng_for
from kitegully.stereo.calibration import calibrate_camera_weighted, distortion_precision
from kitegully.stereo.control_field import (ControlField, calibration_field, calibration_poses, convergent_poses, simulate_observations)
from kitegully.stereo.rig import D2H_PIXEL_MM, camera_to_table, paper_cameras

REPO = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=8)
    a = ap.parse_args()
    cams, field = paper_cameras(), calibration_field()
    designs = {"stage (convergent images aimed at the field centre)": calibration_poses() + convergent_poses(),
               "convergent images with the field in the frame corners (corner_fraction 0.5)": calibration_poses() + convergent_poses(corner_fraction=0.5)}
    lines = ["# Stereo: K1 identifiability with the 32-point field", "",
             f"{a.seeds} seeds; field error 0.2 mm, targets 0.1 px; weighted-control bundle.", "",
             "| design | camera | targets beyond 0.8 of the half-diagonal / all | median abs K1 error (%) | within 10 % | K1 se (% of truth) | median abs error/se | corr(K1,K2) | corner Δr abs error median / max (px) | corner Δr se (px) | abs f error median / max (mm) | f within 0.05 mm |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for name, poses in designs.items():
        for side, cam in cams.items():
            rows = []
            for seed in range(1, a.seeds + 1):
                rng = rng_for(seed, "stereo", "calibration")
                known = ControlField(field.ids, field.xyz + rng.normal(0.0, 0.2e-3, field.xyz.shape))
                obs = simulate_observations(cam, field, poses, 0.1, rng_for(seed, "stereo", "targets", side))
                rmax = np.hypot(cam.width / 2, cam.height / 2)
                far = sum(int((np.hypot(o.uv[:, 0] - cam.cx, o.uv[:, 1] - cam.cy) / rmax > 0.8).sum()) for o in obs)
                res, _ = calibrate_camera_weighted(known, obs, cam.width, cam.height, D2H_PIXEL_MM, 0.1, 2e-4, template=cam, name=side)
                d = distortion_precision(res, cam)
                df = camera_to_table(res.camera)["f_mm"] - camera_to_table(cam)["f_mm"]
                t1 = camera_to_table(cam)["K1"]
                rows.append((far, sum(len(o.ids) for o in obs), abs(d["K1_err_pct"]), 100 * d["K1_se"] / t1, abs(d["K1_err_in_se"]),
                             d["corr_K1_K2"], abs(d["edge_dr_err_px"]), d["edge_dr_se_px"], abs(df)))
                print(name[:20], side, seed, [round(float(v), 4) for v in rows[-1]], flush=True)
            r = np.array(rows)
            lines.append(f"| {name} | {side} | {int(np.median(r[:, 0]))} / {int(np.median(r[:, 1]))} | {np.median(r[:, 2]):.1f} | "
                         f"{int((r[:, 2] < 10).sum())} of {len(r)} | {np.median(r[:, 3]):.0f} | {np.median(r[:, 4]):.2f} | {np.median(r[:, 5]):.2f} | "
                         f"{np.median(r[:, 6]):.3f} / {r[:, 6].max():.3f} | {np.median(r[:, 7]):.3f} | {np.median(r[:, 8]):.4f} / {r[:, 8].max():.4f} | "
                         f"{int((r[:, 8] < 0.05).sum())} of {len(r)} |")
    out = REPO / "benchmarks" / "out"
    out.mkdir(parents=True, exist_ok=True)
    (out / "stereo_k1_identifiability.md").write_text("\n".join(lines) + "\n", encoding="utf-8")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
