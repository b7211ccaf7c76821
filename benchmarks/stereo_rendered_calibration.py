"""Session-10 evidence (issue 19): the 32 calibration targets rendered as 10 mm printed discs into the 14 photographs per camera, located (measure_targets), weighted bundle; errors against the twin truth. PYTHONPATH=src python benchmarks/stereo_rendered_calibration.py (about 12 s CPU)."""
import time

import numpy as np

from kitegully.stereo.calibration import calibrate_camera_weighted, distortion_precision
from kitegully.stereo.calibration_targets import (calibration_targets, measure_targets, projected_disc_offset_px, render_calibration_image)
from kitegully.stereo.control_field import ControlField, calibration_field, calibration_poses, convergent_poses
from kitegully.stereo.measure import PrintedMarks
from kitegully.stereo.rig import paper_cameras, D2H_NOMINAL_F_MM, D2H_PIXEL_MM
from kitegully.seeds import rng_for
from kitegully.twin.camera import Camera
t0 = time.process_time()
cams = paper_cameras()
field = calibration_field(); tg = calibration_targets(field)
poses = calibration_poses() + convergent_poses()
rng = rng_for(42, "stereo", "calibration")
known = ControlField(field.ids, field.xyz + rng.normal(0.0, 0.2e-3, field.xyz.shape))
for side, cam in cams.items():
    nom = Camera(**{**cam.__dict__, "f": D2H_NOMINAL_F_MM / D2H_PIXEL_MM, "cx": (cam.width-1)/2, "cy": (cam.height-1)/2, "k1": 0.0, "k2": 0.0})
    obs, sig, errs, offs = [], [], [], []
    for k, pose in enumerate(poses):
        P = nom.project(field.xyz, pose)
        img = np.full((cam.height, cam.width), np.nan, np.float32)
        r = np.random.default_rng(1000 * k + (side == "right"))
        for i, p in enumerate(P):
            if not (-60 < p[0] < cam.width + 60 and -60 < p[1] < cam.height + 60):
                continue
            near = np.linalg.norm(P - p, axis=1) < 200
            win = (int(p[0]) - 120, int(p[1]) - 120, int(p[0]) + 121, int(p[1]) + 121)
            sub = render_calibration_image(cam, pose, PrintedMarks(field.xyz[near], tg.design), 1.0, r, win)
            x0, y0, x1, y1 = max(0, win[0]), max(0, win[1]), min(cam.width, win[2]), min(cam.height, win[3])
            img[y0:y1, x0:x1] = sub[y0:y1, x0:x1]
        m = measure_targets(img, nom, pose, known, 0.010, 60.0, f"{side} {k + 1}")
        idx = [list(field.ids).index(i) for i in m.observation.ids]
        errs.append(m.observation.uv - cam.project(field.xyz[idx], pose))
        offs.append(projected_disc_offset_px(cam, pose, field.xyz[idx], 0.005))
        obs.append(m.observation); sig.append(m.sigma_px)
        print(side, k, len(idx), f"{time.process_time()-t0:.0f}s", flush=True)
    E = np.vstack(errs); O = np.vstack(offs); S = np.concatenate(sig)
    s_px = float(np.median(S))
    print(side, "n", len(E), "err rms px", np.sqrt((E**2).mean()), "max", np.abs(E).max(), "noise sigma median", s_px,
          "err-offset rms", np.sqrt(((E-O)**2).mean()), "max offset", np.abs(O).max(), flush=True)
    res, _ = calibrate_camera_weighted(known, obs, cam.width, cam.height, D2H_PIXEL_MM, s_px, 0.2e-3, template=cam, name=side)
    d = distortion_precision(res, cam)
    tr = cam
    print(side, "RMS", res.rms_px, "f err mm", (res.camera.f - tr.f) * D2H_PIXEL_MM, "cx err px", res.camera.cx - tr.cx, "cy err px", res.camera.cy - tr.cy,
          "K1 err %", d["K1_err_pct"], "K1 se % of truth", 100 * d["K1_se"] / (cam.k1 / (cam.f * D2H_PIXEL_MM) ** 2), "K1", d["K1"], d["K1_se"], "K2", d["K2"], d["K2_se"],
          "f se mm", d["f_mm_se"], "edge err", d["edge_dr_err_px"], d["edge_dr_se_px"], "corr", d["corr_K1_K2"], flush=True)
    cov = res.covariance; print(side, "se f,cx,cy px", np.sqrt(np.diag(cov))[:3], flush=True)
print("CPU s", time.process_time() - t0)
