#!/usr/bin/env python
"""Stereo (paper 003): K1 over seeds with the stage's rendered targets, with and without corner images.

The stage calibrates each camera on the paper's 6 shifted images and 8 convergent ones aimed at
the field (``stereo.calibration.stations: paper+convergent``), the targets rendered as printed
discs and located in the photographs (``targets: rendered``), with the weighted-control bundle.
Radial distortion (K1 r³ + K2 r⁵) is only told apart from K2 and from f where targets reach the
frame's corners, and of ~400 target images only ~9 lie beyond 0.8 of the half-diagonal. A
calibration in practice also images the field in every part of the format; the second design
adds 8 convergent images turned so the field's centre is imaged half-way to a frame corner
(``convergent_poses(corner_fraction=0.5)``, each corner twice), keeping the 14 of the stage.

For ``--seeds`` draws (field known to 0.2 mm, rendered targets, 1 DN image noise) and both
cameras: K1 error and standard error, corner displacement error, f error, targets beyond 0.8 of
the half-diagonal. Writes ``benchmarks/out/stereo_k1_rendered.csv`` and ``.md``.

Usage: PYTHONPATH=src .venv/bin/python benchmarks/stereo_k1_rendered.py [--seeds 8]
One core, ≈ 0.4 s CPU per rendered image plus the bundle (≈ 10-20 s per calibration).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import pandas as pd

from kitegully.seeds import rng_for
from kitegully.stereo.calibration import calibrate_camera_weighted, distortion_precision
from kitegully.stereo.calibration_targets import measure_calibration_images
from kitegully.stereo.control_field import ControlField, calibration_field, calibration_poses, convergent_poses
from kitegully.stereo.rig import D2H_PIXEL_MM, camera_to_table, paper_cameras
from kitegully.stereo.stage import PREDICTION_ALLOWANCE_PX, _without_io

REPO = Path(__file__).resolve().parents[1]
H_M, OFFSET_M, N_CONV, FIELD_SD_MM, DIAMETER_MM, NOISE_DN = 3.0, 1.5, 8, 0.2, 10.0, 1.0  # the stage's settings (stereo_lab.yaml)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=8)
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "out" / "stereo_k1_rendered"))
    a = ap.parse_args()
    cams, field = paper_cameras(), calibration_field()
    stage = calibration_poses(H_m=H_M) + convergent_poses(H_M, OFFSET_M, N_CONV)
    designs = {"stage (14 images)": stage,
               "stage + 8 corner images (22)": stage + convergent_poses(H_M, OFFSET_M, N_CONV, corner_fraction=0.5)}
    rows = []
    for seed in range(1, a.seeds + 1):
        rng = rng_for(seed, "stereo", "calibration")
        known = ControlField(field.ids, field.xyz + rng.normal(0.0, FIELD_SD_MM * 1e-3, field.xyz.shape))
        for name, poses in designs.items():
            for side, cam in cams.items():
                t0 = time.process_time()
                obs, sigma = measure_calibration_images(cam, _without_io(cam, True, True, True), field, known, poses, DIAMETER_MM * 1e-3,
                                                        NOISE_DN, rng_for(seed, "stereo", "target_images", side), PREDICTION_ALLOWANCE_PX, side)
                res, _ = calibrate_camera_weighted(known, obs, cam.width, cam.height, D2H_PIXEL_MM, sigma, FIELD_SD_MM * 1e-3,
                                                   template=cam, name=side)
                d = distortion_precision(res, cam)
                rmax = np.hypot(cam.width / 2, cam.height / 2)
                far = sum(int((np.hypot(o.uv[:, 0] - cam.cx, o.uv[:, 1] - cam.cy) / rmax > 0.8).sum()) for o in obs)
                rows.append({"seed": seed, "design": name, "camera": side, "targets": sum(len(o.ids) for o in obs), "beyond_0.8": far,
                             "centroid_sigma_px": sigma, "rms_px": res.rms_px, "K1_err_pct": d["K1_err_pct"],
                             "K1_se_pct": 100 * d["K1_se"] / camera_to_table(cam)["K1"], "corr_K1_K2": d["corr_K1_K2"],
                             "edge_dr_err_px": d["edge_dr_err_px"], "edge_dr_se_px": d["edge_dr_se_px"],
                             "f_err_mm": camera_to_table(res.camera)["f_mm"] - camera_to_table(cam)["f_mm"], "cpu_s": time.process_time() - t0})
                print({k: (round(v, 4) if isinstance(v, float) else v) for k, v in rows[-1].items()}, flush=True)
    df = pd.DataFrame(rows)
    out = Path(a.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    df.to_csv(out.with_suffix(".csv"), index=False)
    g = df.assign(abs_k1=df["K1_err_pct"].abs(), abs_f=df["f_err_mm"].abs(), abs_dr=df["edge_dr_err_px"].abs()).groupby(["design", "camera"], sort=False)
    summ = g.agg(seeds=("seed", "size"), beyond_08=("beyond_0.8", "median"), K1_abs_err_median_pct=("abs_k1", "median"),
                 K1_abs_err_max_pct=("abs_k1", "max"), K1_within_10pct=("abs_k1", lambda v: int((v <= 10).sum())),
                 K1_se_median_pct=("K1_se_pct", "median"), edge_dr_abs_err_median_px=("abs_dr", "median"),
                 f_abs_err_median_mm=("abs_f", "median"), f_abs_err_max_mm=("abs_f", "max"),
                 f_within_005=("abs_f", lambda v: int((v <= 0.05).sum())), cpu_s_median=("cpu_s", "median")).reset_index()
    text = ("# Stereo: K1 over seeds with rendered targets\n\n" + f"{a.seeds} seeds; field known to 0.2 mm; targets rendered (1 DN noise) and located; "
            "weighted-control bundle. Targets: K1 within 10 %, f within 0.05 mm.\n\n" + summ.to_markdown(index=False, floatfmt=".3g") + "\n")
    out.with_suffix(".md").write_text(text, encoding="utf-8")
    print(text)


if __name__ == "__main__":
    main()
