"""The ``stereo`` stage: the paper's lab runs on a stereo-rig twin (Moritani et al. 2010, issue 19).

Entry points, one per rule, named after what they make:

* :func:`calibrate_rig` — Table 1 regenerated (``calibration.csv``) and the calibration test
  (H = 2–6 m, B = 1.0 m, with and without inner orientation, ``calibration_test.csv`` + figure);
  writes the calibrated cameras (JSON) that every later run processes with.
* :func:`measure_dry_box` — 11 set-ups (point and surface MAE vs L, both fits and the δz
  model line) and the 16 removals at L = 9.1 m (``A = b·M``).
* :func:`measure_rain` — the three bulk densities under 60 mm/h for 1 h on 10°.
* :func:`measure_wind` — the wind-tunnel tray, before/after.

Every pair is made in two separate steps: a *twin* step renders the two photographs of
the true surface through the true cameras (:mod:`kitegully.stereo.lab`), and a *processing* step
sees only what the paper had — the photographs, the calibrated cameras and the surveyed
coordinates of the 10 printed frame marks — measures tie points (SIFT) and the marks
(template + weighted centroid, :mod:`kitegully.stereo.measure`) in the photographs and returns
a DEM (:meth:`kitegully.stereo.processing.PairProcessor.from_images`).
Only the evaluation (MAE against the point gauge or the gravimetric depth,
:mod:`kitegully.stereo.evaluation`) reads the reference, as the paper's did. Parameters:
:class:`kitegully.stereo.params.StereoParams`; the rain runs' process models:
:mod:`kitegully.stereo.erosion`.
"""

from __future__ import annotations

import json
import logging
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping

import numpy as np
import pandas as pd

from kitegully import InputError
from kitegully.georef.similarity import umeyama
from kitegully.io.figures import new_figure, save_figure
from kitegully.io.tables import write_table
from kitegully.seeds import rng_for
from kitegully.stereo.calibration import (calibrate_camera, calibrate_camera_weighted, calibration_table, distortion_precision)
from kitegully.stereo.calibration_targets import measure_calibration_images
from kitegully.stereo.control_field import (ControlField, calibration_field, calibration_poses, convergent_poses, simulate_observations)
from kitegully.stereo.erosion import interrill_rate_kg_m2_h, runoff_detachment_kg_m2_h, settlement_mm
from kitegully.stereo.evaluation import error_decomposition, matching_residual_px, pair_columns
from kitegully.stereo.lab import (BOX, TEXTURE_EXTENT, box_grid, cell_truth, frame_marks, nail_positions, relief,
                                  render_pair, survey_marks)
from kitegully.stereo.matching import MatchParams, triangulate_points
from kitegully.stereo.measure import MarkDesign, PrintedMarks
from kitegully.stereo.metrics import fit_A_vs_M, fit_mae_vs_L, mae, mre
from kitegully.stereo.params import StereoParams, as_floats
from kitegully.stereo.processing import PairProcessor
from kitegully.stereo.rectify import rectify_pair, relative_orientation
from kitegully.stereo.rig import D2H_NOMINAL_F_MM, D2H_PIXEL_MM, delta_z_m, paper_cameras, paper_rig, stereo_L_m
from kitegully.stereo.synth import soil_texture
from kitegully.twin.camera import Camera, Pose

if TYPE_CHECKING:
    from kitegully.io.raster import GridSpec

log = logging.getLogger(__name__)

#: Matching precision (px) of the LoG coarse-to-fine matcher on the rendered soil, measured against the
#: ray-cast true disparity by benchmarks/stereo_benchmark.py (0.043-0.050 px over L = 5.8-35 m; 0.046 at 9.1 m).
MATCHING_PRECISION_PX = 0.046

PAPER = {"a_calibration_without_io": 0.74, "a_calibration_with_io": 0.057, "a_point": 0.049, "a_surface": 0.030,
         "b": 1.06, "mae_9_1_mm": 0.21, "mre_9_1_pct": 15.8, "wind_mae_mm": 0.21, "upstream_minus_downstream_mm": 0.49,
         "rain": {0.91: (2.21, 392.5), 0.98: (1.07, 126.4), 1.09: (0.59, 57.6)}}



def _load_cameras(path: str | Path) -> dict[str, Camera]:
    data = json.loads(Path(path).read_text(encoding="utf-8"))
    try:
        return {side: Camera(**data[side]) for side in ("left", "right")}
    except (KeyError, TypeError) as exc:
        raise InputError(f"{path}: not a calibrated stereo camera file (needs 'left' and 'right' cameras): {exc}") from None


def _dod_figure(dod: np.ndarray, grid: GridSpec, title: str, path: str | Path) -> None:
    fig, ax = new_figure(figsize=(4.2, 5.0))
    v = np.nanpercentile(np.abs(dod), 98) if np.isfinite(dod).any() else 1.0
    x0, y0, x1, y1 = grid.bounds
    im = ax.imshow(dod, cmap="RdBu", vmin=-v, vmax=v, extent=(1e3 * x0, 1e3 * x1, 1e3 * y0, 1e3 * y1))
    fig.colorbar(im, ax=ax, label="DEM of difference, after − before (mm)")
    ax.set_xlabel("x along the base (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_title(title)
    save_figure(fig, path, "kitegully stereo twin after Moritani et al. (2010)")


# ----------------------------------------------------------------------------- rule: calibration
#: [I] bound on the prediction error of a target through the nominal 50 mm lens: 2.8 % of f (51.4 vs 50 mm) at the
#: 1480 px half-diagonal = 41 px, + principal point (≤ 10 px) + distortion (≤ 4 px) ≈ 55 px → 60 px.
PREDICTION_ALLOWANCE_PX = 60.0


def _calibrate(cams_true, params: StereoParams, seed: int, stations: str, weighted: bool):
    c = params.calibration
    rng = rng_for(seed, "stereo", "calibration")
    field = calibration_field()
    poses = calibration_poses(H_m=c["H_m"])
    if stations.startswith("paper+convergent"):
        poses = poses + convergent_poses(c["H_m"], c["convergent_offset_m"], int(c["n_convergent"]))
    if stations == "paper+convergent+corners":
        poses = poses + convergent_poses(c["H_m"], c["convergent_offset_m"], int(c.get("n_corner", 8)),
                                         corner_fraction=float(c.get("corner_fraction", 0.5)))
    known = ControlField(field.ids, field.xyz + rng.normal(0.0, c["field_sigma_mm"] * 1e-3, field.xyz.shape))
    out = {}
    for side, cam in cams_true.items():
        sigma = c["target_sigma_px"]
        if c.get("targets", "simulated") == "rendered":
            # targets rendered as printed discs and located in the photographs; predicted through the nominal lens
            nom = _without_io(cam, True, True, True)
            obs, sigma = measure_calibration_images(cam, nom, field, known, poses, c["target_diameter_mm"] * 1e-3, c["image_noise_dn"],
                                                    rng_for(seed, "stereo", "target_images", side), PREDICTION_ALLOWANCE_PX, side)
            log.info("%s: %d targets measured in %d rendered photographs, median centroid σ %.4f px", side,
                     sum(len(o.ids) for o in obs), len(obs), sigma)
        else:
            obs = simulate_observations(cam, field, poses, sigma, rng_for(seed, "stereo", "targets", side))
        if weighted:
            out[side] = calibrate_camera_weighted(known, obs, cam.width, cam.height, D2H_PIXEL_MM, sigma,
                                                  c["field_sigma_mm"] * 1e-3, template=cam, name=side)[0]
        else:
            out[side] = calibrate_camera(known, obs, cam.width, cam.height, D2H_PIXEL_MM, template=cam, name=side)
    return out, field


def _without_io(cam: Camera, nominal_f: bool, no_distortion: bool, centred_pp: bool) -> Camera:
    """The camera as processed without (part of) its inner orientation: nominal 50 mm, no distortion, centred principal point."""
    kw = dict(cam.__dict__)
    if nominal_f:
        kw["f"] = D2H_NOMINAL_F_MM / D2H_PIXEL_MM
    if no_distortion:
        kw["k1"] = kw["k2"] = 0.0
    if centred_pp:
        kw["cx"], kw["cy"] = (cam.width - 1) / 2.0, (cam.height - 1) / 2.0
    return Camera(**kw)


def calibrate_rig(cfg: Mapping[str, Any], seed: int, out: Mapping[str, str]) -> None:
    """Rule ``stereo_calibrate``: Table 1, the calibration test and the calibrated cameras.

    Parameters
    ----------
    cfg : mapping
        ``stereo.calibration``, ``stereo.calibration_test`` and ``stereo.processing``.
    seed : int
        Master seed.
    out : mapping
        Paths ``calibration`` (csv), ``cameras`` (json), ``test`` (csv), ``test_png``.
    """
    params = StereoParams.from_config(cfg)
    t0 = time.perf_counter()
    cams_true = paper_cameras()
    c = params.calibration
    chosen, field = _calibrate(cams_true, params, seed, c["stations"], bool(c["weighted_control"]))
    paper_proto, _ = _calibrate(cams_true, params, seed, "paper", False)
    tab = calibration_table(chosen, cams_true)
    alt = calibration_table(paper_proto, cams_true)
    tab.insert(4, "recovered_paper_protocol", alt["recovered"].to_numpy())
    tab["error_paper_protocol"] = alt["error"].to_numpy()
    tab["rms_px"] = [chosen[s].rms_px for s in tab["camera"]]
    if all(r.covariance is not None for r in chosen.values()):
        # K1 with its standard error, its correlations and the displacement it causes at the frame corner (what a DEM sees)
        prec = {s: distortion_precision(r, cams_true[s]) for s, r in chosen.items()}
        for key in ("K1_se", "corr_K1_K2", "corr_K1_f", "edge_dr_px", "edge_dr_se_px", "edge_dr_err_px", "K1_err_in_se"):
            tab[key] = [prec[s][key] for s in tab["camera"]]
        log.info("calibration: K1 %s", {s: f"{p['K1']:.3g} ± {p['K1_se']:.2g} (truth error {p['K1_err_pct']:+.1f} %, corner Δr error "
                                          f"{p['edge_dr_err_px']:+.3f} ± {p['edge_dr_se_px']:.3f} px)" for s, p in prec.items()})
    tab["method"] = f"{c['stations']} stations, " + ("weighted control" if c["weighted_control"] else "fixed control")
    write_table(tab, out["calibration"])
    cams = {s: r.camera for s, r in chosen.items()}
    Path(out["cameras"]).write_text(json.dumps({s: cam.__dict__ for s, cam in cams.items()}, indent=1), encoding="utf-8")
    log.info("calibration: f errors %s mm", {s: round(float(tab.loc[(tab.camera == s) & (tab.parameter == 'f'), 'error'].iloc[0]), 4) for s in cams})

    # calibration test: the field seen by the rig at 5 heights; processed with and without inner orientation
    ct = params.calibration_test
    nominal = {s: _without_io(cam, True, True, True) for s, cam in cams.items()}
    # [I] ablation: which part of the inner orientation the "without" error comes from (each left out alone)
    variants = [("with inner orientation", cams), ("without inner orientation", nominal),
                ("without: nominal f only", {s: _without_io(cam, True, False, False) for s, cam in cams.items()}),
                ("without: no distortion only", {s: _without_io(cam, False, True, False) for s, cam in cams.items()}),
                ("without: centred principal point only", {s: _without_io(cam, False, False, True) for s, cam in cams.items()})]
    rows = []
    sig = c["target_sigma_px"]
    for H in as_floats(ct["H_m"], "stereo.calibration_test.H_m"):
        B = float(ct["B_m"])
        rng = rng_for(seed, "stereo", "calibration_test", f"{H}")
        truth = paper_rig(H, B, centre_xy=(0.0, 0.0))
        ul = truth.left.project(field.xyz, truth.pose_left) + rng.normal(0, sig, (len(field.xyz), 2))
        ur = truth.right.project(field.xyz, truth.pose_right) + rng.normal(0, sig, (len(field.xyz), 2))
        surveyed = field.xyz + rng.normal(0, c["field_sigma_mm"] * 1e-3, field.xyz.shape)
        gcp = np.arange(0, 32, 3)[:10]
        chk = np.setdiff1d(np.arange(32), gcp)
        for label, cset in variants:
            R, T, _ = relative_orientation(cset["left"], cset["right"], ul, ur, B)
            rect = rectify_pair(cset["left"], cset["right"], R, T, (H - 0.5, H + 0.5))
            P = triangulate_points(rect, rect.rectify_points(ul, "left"), rect.rectify_points(ur, "right"), Pose(np.eye(3), np.zeros(3)))
            sim = umeyama(P[gcp], surveyed[gcp])
            err = sim.apply(P[chk]) - field.xyz[chk]
            rows.append({"H_m": H, "B_m": B, "L_m": float(stereo_L_m(H, B)), "processing": label,
                         "mae_z_mm": 1e3 * float(np.mean(np.abs(err[:, 2]))), "mae_3d_mm": 1e3 * float(np.mean(np.linalg.norm(err, axis=1))),
                         "check_points": len(chk)})
    test = pd.DataFrame(rows)
    fits = {}
    for label, g in test.groupby("processing"):
        fits[label] = fit_mae_vs_L(g["L_m"], g["mae_z_mm"])
    test["a_fit_mm_per_m"] = [fits[p][0] for p in test["processing"]]
    test["r2_fit"] = [fits[p][1] for p in test["processing"]]
    test["a_paper_mm_per_m"] = [PAPER["a_calibration_with_io"] if p.startswith("with ") else
                                PAPER["a_calibration_without_io"] if p == "without inner orientation" else np.nan for p in test["processing"]]
    # the paper's a without inner orientation as a disparity error: constant bias of a/(δ_CCD/f) px
    test["paper_a_as_disparity_bias_px"] = PAPER["a_calibration_without_io"] / (1e3 * D2H_PIXEL_MM / D2H_NOMINAL_F_MM)
    write_table(test, out["test"])
    fig, ax = new_figure(figsize=(5.5, 3.8))
    Ls = np.linspace(0, test["L_m"].max() * 1.05, 50)
    for label, colour in (("with inner orientation", "tab:blue"), ("without inner orientation", "tab:red")):
        g = test[test.processing == label]
        ax.plot(g["L_m"], g["mae_z_mm"], "o", color=colour, label=f"{label}: a = {fits[label][0]:.4f} mm/m")
        ax.plot(Ls, fits[label][0] * Ls, "-", color=colour)
        ax.plot(Ls, g["a_paper_mm_per_m"].iloc[0] * Ls, ":", color=colour, label=f"paper a = {g['a_paper_mm_per_m'].iloc[0]} mm/m")
    for (label, mk) in zip([v[0] for v in variants[2:]], ("^", "v", "x")):
        g = test[test.processing == label]
        ax.plot(g["L_m"], g["mae_z_mm"], mk, color="0.4", ms=4, label=label)
    ax.set_yscale("symlog", linthresh=0.05)
    ax.set_xlabel("L = H²/B (m)")
    ax.set_ylabel("MAE of height at 22 check targets (mm)")
    ax.legend()
    save_figure(fig, out["test_png"], "kitegully stereo twin after Moritani et al. (2010)")
    log.info("calibration rule done in %.1f s", time.perf_counter() - t0)


# ----------------------------------------------------------------------------- rule: dry box
def measure_dry_box(cfg: Mapping[str, Any], cameras_json: str, seed: int, out: Mapping[str, str]) -> None:
    """Rule ``stereo_dry_box``: MAE vs L over the 11 set-ups and the 16 removals at L = 9.1 m.

    Parameters
    ----------
    cfg : mapping
        ``stereo.processing`` and ``stereo.dry_box``.
    cameras_json : str
        Calibrated cameras from :func:`calibrate_rig`.
    seed : int
    out : mapping
        ``mae_vs_L`` (csv), ``mae_vs_L_png``, ``removals`` (csv), ``removals_png``, ``dod_png``.

    Notes
    -----
    Cost: 11 + 17 rendered pairs of the box window (0.1–1 Mpx each) and their matching;
    about a minute on one core.
    """
    params = StereoParams.from_config(cfg)
    cams = _load_cameras(cameras_json)
    proc, db = params.processing, params.dry_box
    texture = soil_texture(rng_for(seed, "stereo", "texture"), TEXTURE_EXTENT)
    grid = box_grid(proc["cell_mm"] * 1e-3)
    ref = cell_truth(relief, grid)
    extent = np.array([[x, y, z] for x in (BOX[0], BOX[2]) for y in (BOX[1], BOX[3]) for z in (-0.01, 0.01)])  # the soil, not the frame
    diameter = proc["mark_diameter_mm"] * 1e-3
    marks = PrintedMarks(frame_marks(), MarkDesign(diameter))
    match = MatchParams(**proc["matching"])
    rows = []
    for H, B in (tuple(float(v) for v in s) for s in db["setups"]):
        rng = rng_for(seed, "stereo", "dry_box", f"{H}-{B}")
        truth = paper_rig(H, B)
        L_img, R_img = render_pair(truth, relief, texture, proc["image_noise_dn"], rng, extent, marks)
        pp = PairProcessor.from_images(cams, L_img, R_img, survey_marks(marks.xyz, rng, proc), diameter, B, H, match)
        dem, n, disp = pp.dem(L_img, R_img, grid, return_disparity=True)
        ok = dem.valid
        # evaluation: the achieved matching precision δ (px) and the DEM error split into plane + rest
        prec = matching_residual_px(pp.rect, disp, truth, relief, grid)
        dec = error_decomposition(dem.data, ref, grid)
        # point measurement: 20 nail heads matched by hand, against the point gauge (±0.01 mm)
        nails = nail_positions(rng)
        heads = np.column_stack([nails, relief(nails[:, 0], nails[:, 1]) + 0.02])
        gauge = heads[:, 2] + rng.normal(0, 1e-5, len(heads))
        ms = proc["manual_sigma_px"]
        P = pp.points(truth.left.project(heads, truth.pose_left) + rng.normal(0, ms, (20, 2)),
                      truth.right.project(heads, truth.pose_right) + rng.normal(0, ms, (20, 2)))
        dz_model = delta_z_m(H, B, cams["left"]) * 1e3
        rows.append({"H_m": H, "B_m": B, "L_m": float(stereo_L_m(H, B)), "matched_px": n,
                     "point_mae_mm": 1e3 * mae(gauge, P[:, 2]), "surface_mae_mm": 1e3 * mae(ref[ok], dem.data[ok]),
                     "surface_mean_error_mm": 1e3 * float(np.mean(dem.data[ok] - ref[ok])), "dem_cover_pct": 100 * float(ok.mean()),
                     "dz_1px_mm": dz_model, "sigma_d_px": prec["sigma_d_px"], "bias_d_px": prec["bias_d_px"],
                     "y_parallax_rms_px": prec["y_parallax_rms_px"], "surface_tilt_error_mm_per_m": dec["tilt_mm_per_m"],
                     "surface_plane_mae_mm": dec["plane_mae_mm"], "surface_residual_mae_mm": dec["residual_mae_mm"],
                     **pair_columns(pp, truth, marks.xyz)})
        log.info("dry box H %.2f B %.2f: point MAE %.3f mm, surface MAE %.3f mm; %d tie points (Sampson RMS %.3f px), "
                 "marks %.4f px from the truth, similarity residual %.3f mm", H, B, rows[-1]["point_mae_mm"], rows[-1]["surface_mae_mm"],
                 pp.info["ties_inliers"], pp.info["tie_sampson_rms_px"], rows[-1]["mark_error_px"], pp.info["mark_abs_rms_mm"])
    tab = pd.DataFrame(rows)
    a_pt, r2_pt = fit_mae_vs_L(tab["L_m"], tab["point_mae_mm"])
    a_s, r2_s = fit_mae_vs_L(tab["L_m"], tab["surface_mae_mm"])
    # σ_d equivalent: the matching precision that would explain the surface MAE through the δz model alone
    # (the stage has no true disparity; the matcher's own σ_d is MATCHING_PRECISION_PX, measured by the benchmark)
    sd = float(np.sum(tab["surface_mae_mm"] * tab["dz_1px_mm"]) / np.sum(tab["dz_1px_mm"] ** 2)) / np.sqrt(2 / np.pi)
    tab["a_point_fit_mm_per_m"], tab["r2_point"], tab["a_surface_fit_mm_per_m"], tab["r2_surface"] = a_pt, r2_pt, a_s, r2_s
    tab["a_point_paper"], tab["a_surface_paper"] = PAPER["a_point"], PAPER["a_surface"]
    tab["dz_model_slope_per_px_mm_per_m"] = float(np.mean(tab["dz_1px_mm"] / tab["L_m"]))
    tab["sigma_d_equivalent_px"] = sd
    tab["dz_model_a_mm_per_m"] = float(np.sqrt(2 / np.pi) * np.mean(tab["dz_1px_mm"] / tab["L_m"]) * MATCHING_PRECISION_PX)
    # the δz model at the precision achieved in this run (δ measured per set-up against the twin's surface)
    delta = float(np.nanmedian(tab["sigma_d_px"]))
    k = float(np.mean(tab["dz_1px_mm"] / tab["L_m"]))
    tab["sigma_d_measured_median_px"] = delta
    tab["dz_model_a_measured_mm_per_m"] = float(np.sqrt(2 / np.pi) * k * delta)
    a_res, r2_res = fit_mae_vs_L(tab["L_m"], tab["surface_residual_mae_mm"])
    a_pl, r2_pl = fit_mae_vs_L(tab["L_m"], tab["surface_plane_mae_mm"])
    tab["a_surface_residual_mm_per_m"], tab["r2_surface_residual"] = a_res, r2_res
    tab["a_surface_plane_mm_per_m"], tab["r2_surface_plane"] = a_pl, r2_pl
    # [I] what the image measurement of the 10 frame marks alone predicts for the box-mean height:
    # each mark's height from a disparity measured to √2·σ_mark px (σ_mark: the marks' measured error), averaged over 10 marks
    tab["dz_model_a_marks_offset_mm_per_m"] = float(np.sqrt(2 / np.pi) * k * np.sqrt(2) * np.median(tab["mark_error_px"]) / np.sqrt(10))
    log.info("dry box: δ = %.3f px; surface a = %.4f (plane part %.4f, rest %.4f) vs δz model %.4f mm/m",
             delta, a_s, a_pl, a_res, float(np.sqrt(2 / np.pi) * k * delta))
    write_table(tab, out["mae_vs_L"])
    fig, ax = new_figure(figsize=(5.5, 3.8))
    Ls = np.linspace(0, tab["L_m"].max() * 1.05, 50)
    k = float(np.mean(tab["dz_1px_mm"] / tab["L_m"]))
    ax.plot(tab["L_m"], tab["point_mae_mm"], "s", color="tab:orange", label=f"point (20 nails): a = {a_pt:.4f} mm/m")
    ax.plot(Ls, a_pt * Ls, "-", color="tab:orange")
    ax.plot(tab["L_m"], tab["surface_mae_mm"], "o", color="tab:blue", label=f"surface (DEM): a = {a_s:.4f} mm/m")
    ax.plot(Ls, a_s * Ls, "-", color="tab:blue")
    ax.plot(tab["L_m"], tab["surface_residual_mae_mm"], "d", color="tab:green", ms=4,
            label=f"surface minus its error plane: a = {a_res:.4f} mm/m")
    ax.plot(Ls, np.sqrt(2 / np.pi) * k * delta * Ls, "--", color="k",
            label=f"δz model, MAE = √(2/π)·L·δ_CCD·δ/f, δ = {delta:.3f} px (measured)")
    ax.plot(Ls, PAPER["a_point"] * Ls, ":", color="tab:orange", label="paper point a = 0.049")
    ax.plot(Ls, PAPER["a_surface"] * Ls, ":", color="tab:blue", label="paper surface a = 0.030")
    ax.set_xlabel("L = H²/B (m)")
    ax.set_ylabel("MAE (mm)")
    ax.legend(fontsize=7)
    save_figure(fig, out["mae_vs_L_png"], "kitegully stereo twin after Moritani et al. (2010)")

    # 16 removals at L = 9.1 m
    H, B = float(db["removal_H_m"]), float(db["removal_B_m"])
    rng = rng_for(seed, "stereo", "removals")
    truth = paper_rig(H, B)
    surveyed = survey_marks(marks.xyz, rng, proc)
    S_cm2 = (BOX[2] - BOX[0]) * (BOX[3] - BOX[1]) * 1e4
    rho = float(db["bulk_density"])
    V_m3 = float(db["removal_ml"]) * 1e-6
    phases = rng.uniform(0, 2 * np.pi, (int(db["removals"]), 2))
    lx, ly = BOX[2] - BOX[0], BOX[3] - BOX[1]

    def surface(k):
        # removal j lowers the soil by (V/S)·(1 + ½·cos(2πx/lx + φj)·cos(2πy/ly + ψj)) [I]: uneven scraping
        # whose mean over the box is exactly V/S. The sum over j collapses to two complex phasors
        # (cos a·cos b = ½[cos(a+b) + cos(a−b)]), so a state costs 4 trig evaluations, not 2k.
        c1 = np.exp(1j * (phases[:k, 0] + phases[:k, 1])).sum()
        c2 = np.exp(1j * (phases[:k, 0] - phases[:k, 1])).sum()
        d = V_m3 / (S_cm2 * 1e-4)

        def h(x, y):
            u, v = 2 * np.pi * x / lx, 2 * np.pi * y / ly
            wsum = k + 0.25 * (np.real(np.exp(1j * (u + v)) * c1) + np.real(np.exp(1j * (u - v)) * c2))
            return relief(x, y) - d * wsum
        return h

    # [I] scraping soil off exposes new soil: each state has its own texture, so the matching
    # errors of two epochs are independent (the same texture would cancel them in the DoD)
    imgs0 = render_pair(truth, surface(0), texture, proc["image_noise_dn"], rng, extent, marks)
    pp = PairProcessor.from_images(cams, *imgs0, surveyed, diameter, B, H, match)
    d0, _ = pp.dem(*imgs0, grid)
    rrows, marks_uv = [], [np.hstack(pp.info["marks_uv"])]
    for k in range(1, int(db["removals"]) + 1):
        tex_k = soil_texture(rng_for(seed, "stereo", "texture_removal", k), TEXTURE_EXTENT)
        imgs = render_pair(truth, surface(k), tex_k, proc["image_noise_dn"], rng, extent, marks)
        ppk = pp.reoriented_from_images(*imgs) if proc["reorient_each_pair"] else pp
        marks_uv.append(np.hstack(ppk.info["marks_uv"]))
        dk, _ = ppk.dem(*imgs, grid)
        ok = d0.valid & dk.valid
        mass_g = rho * k * V_m3 * 1e6 + rng.normal(0, 0.1)  # balance read to 0.1 g [I]
        M = 10 * mass_g / (rho * S_cm2)
        A = -1e3 * float(np.mean(dk.data[ok] - d0.data[ok]))
        rrows.append({"removal": k, "removed_ml": k * float(db["removal_ml"]), "mass_g": mass_g, "M_s_mm": M, "A_s_mm": A,
                      "abs_error_mm": abs(A - M), "rel_error_pct": 100 * abs(A - M) / M})
        if k == int(db["removals"]):
            _dod_figure(dk.data - d0.data, grid, f"Dry box, {k} removals (L = {stereo_L_m(H, B):.1f} m)", out["dod_png"])
    rem = pd.DataFrame(rrows)
    # repeatability of the mark measurement: the rig does not move between removals, so each mark's
    # position scatters over the 17 pairs by the measurement alone (std per coordinate, RMS over marks and images)
    rem["mark_repeatability_px"] = float(np.sqrt(np.mean(np.std(np.array(marks_uv), axis=0, ddof=1) ** 2)))
    for key, v in pair_columns(pp, truth, marks.xyz).items():
        rem[f"first_pair_{key}"] = v
    b, r2 = fit_A_vs_M(rem["M_s_mm"], rem["A_s_mm"])
    rem["b_fit"], rem["r2_fit"] = b, r2
    rem["MAE_mm"], rem["MRE_pct"] = mae(rem["M_s_mm"], rem["A_s_mm"]), mre(rem["M_s_mm"], rem["A_s_mm"])
    rem["b_paper"], rem["MAE_paper_mm"], rem["MRE_paper_pct"] = PAPER["b"], PAPER["mae_9_1_mm"], PAPER["mre_9_1_pct"]
    write_table(rem, out["removals"])
    fig, ax = new_figure(figsize=(4.5, 4.0))
    ax.plot(rem["M_s_mm"], rem["A_s_mm"], "o", label=f"removals: b = {b:.3f} (R² {r2:.3f})")
    m = np.linspace(0, rem["M_s_mm"].max() * 1.05, 20)
    ax.plot(m, b * m, "-", label="fit A = b·M")
    ax.plot(m, PAPER["b"] * m, ":", label="paper b = 1.06")
    ax.set_xlabel("gravimetric depth M_s (mm)")
    ax.set_ylabel("DEM lowering A_s (mm)")
    ax.legend()
    save_figure(fig, out["removals_png"], "kitegully stereo twin after Moritani et al. (2010)")


# ----------------------------------------------------------------------------- rule: rain
def measure_rain(cfg: Mapping[str, Any], cameras_json: str, seed: int, out: Mapping[str, str]) -> None:
    """Rule ``stereo_rain``: the three bulk densities, a pair every ``interval_min``; MAE, MRE, upstream–downstream.

    Parameters
    ----------
    cfg : mapping
        ``stereo.processing`` and ``stereo.rain``.
    cameras_json : str
    seed : int
    out : mapping
        ``rain_runs`` (csv), ``rain_series`` (csv) and ``dod_png_<i>`` per density.
    """
    params = StereoParams.from_config(cfg)
    cams = _load_cameras(cameras_json)
    proc, rn = params.processing, params.rain
    texture = soil_texture(rng_for(seed, "stereo", "texture_rain"), TEXTURE_EXTENT)
    tan = np.tan(np.radians(rn["slope_deg"]))
    grid = box_grid(proc["cell_mm"] * 1e-3)
    extent = np.array([[x, y, -tan * y + dz] for x in (BOX[0], BOX[2]) for y in (BOX[1], BOX[3]) for dz in (-0.01, 0.01)])
    S_cm2 = (BOX[2] - BOX[0]) * (BOX[3] - BOX[1]) * 1e4
    rate = interrill_rate_kg_m2_h(rn["interrill_erodibility"], rn["intensity_mm_h"], rn["slope_deg"])

    def erosion_rate(y):
        """Total detachment (kg/m²/h) at y: interrill + runoff-driven flow detachment (distance from the upslope wall)."""
        return rate + runoff_detachment_kg_m2_h(np.clip(np.asarray(y, float) - BOX[1], 0.0, None), rn["intensity_mm_h"], rn["ksat_mm_h"],
                                                rn["slope_deg"], rn["manning_n"], rn["rill_erodibility_s_m"], rn["critical_shear_pa"])[1]

    # the model's own upstream − downstream difference of erosion per hour (central 80 % of the box, halves along y)
    yy = np.linspace(BOX[1], BOX[3], 2001)
    ys = np.sqrt(0.8) * (BOX[3] - BOX[1]) / 2
    e_up = float(np.mean(erosion_rate(yy[(yy >= -ys) & (yy < 0)])))
    e_down = float(np.mean(erosion_rate(yy[(yy >= 0) & (yy <= ys)])))
    tau_max = float(runoff_detachment_kg_m2_h(np.array([BOX[3] - BOX[1]]), rn["intensity_mm_h"], rn["ksat_mm_h"], rn["slope_deg"],
                                              rn["manning_n"], rn["rill_erodibility_s_m"], rn["critical_shear_pa"])[0][0])
    box_rate = float(np.mean(erosion_rate(yy)))  # kg/m²/h over the whole box: what leaves it as sediment
    diameter = proc["mark_diameter_mm"] * 1e-3
    match = MatchParams(**proc["matching"])
    times = np.arange(0, rn["duration_min"] + 1e-9, rn["interval_min"])
    runs, series = [], []
    for i, rho in enumerate(as_floats(rn["bulk_densities"], "stereo.rain.bulk_densities")):
        rng = rng_for(seed, "stereo", "rain", f"{rho}")
        s_max = settlement_mm(rho, rn["seal_depth_mm"], rn["seal_density"])
        truth = paper_rig(rn["H_m"], rn["B_m"])
        # the box slopes down towards +y (y = −0.25 m is upstream), 10°
        # the frame slopes with the box: its marks 1 cm above the sloping soil, on plates parallel to it
        marks = PrintedMarks(frame_marks() + np.c_[np.zeros((10, 2)), -tan * frame_marks()[:, 1]], MarkDesign(diameter), dz_dy=-tan)
        surveyed = survey_marks(marks.xyz, rng, proc)

        def surface(t_min, rho=rho, s_max=s_max):
            settle = s_max * (1 - np.exp(-t_min / rn["settle_min"])) * 1e-3
            # m of soil at ρ_b: uniform interrill detachment + flow detachment growing with the runoff from the upslope wall
            return lambda x, y: -tan * y + relief(x, y) - settle - erosion_rate(y) * t_min / 60.0 / (rho * 1e3)

        imgs0 = render_pair(truth, surface(0.0), texture, proc["image_noise_dn"], rng, extent, marks)
        pp = PairProcessor.from_images(cams, *imgs0, surveyed, diameter, rn["B_m"], rn["H_m"], match)
        d0, _ = pp.dem(*imgs0, grid)
        Ms, As, up_down = [], [], None
        for t in times[1:]:
            # [I] splash and wash rearrange the surface grains: a new texture per pair
            tex_t = soil_texture(rng_for(seed, "stereo", "texture_rain", f"{rho}", int(t)), TEXTURE_EXTENT)
            imgs = render_pair(truth, surface(float(t)), tex_t, proc["image_noise_dn"], rng, extent, marks)
            ppt = pp.reoriented_from_images(*imgs) if proc["reorient_each_pair"] else pp
            dt_, _ = ppt.dem(*imgs, grid)
            ok = d0.valid & dt_.valid
            mass = box_rate * 1e3 / 1e4 * S_cm2 * t / 60.0 + rng.normal(0, 0.1)  # g of oven-dry sediment
            M = 10 * mass / (rho * S_cm2)
            lower = -(dt_.data - d0.data) * 1e3
            A = float(np.mean(lower[ok]))
            Ms.append(M)
            As.append(A)
            series.append({"bulk_density_g_cm3": rho, "t_min": float(t), "M_s_mm": M, "A_s_mm": A,
                           "settlement_true_mm": s_max * (1 - np.exp(-t / rn["settle_min"]))})
            if t == times[-1]:
                half = grid.height // 2  # rows: north (y large, downstream) first
                up = np.nanmean(np.where(ok, lower, np.nan)[half:])
                down = np.nanmean(np.where(ok, lower, np.nan)[:half])
                up_down = float(up - down)
                _dod_figure(dt_.data - d0.data, grid, f"Rain, ρ_b {rho} g/cm³, {t:.0f} min", out[f"dod_png_{i}"])
        runs.append({"bulk_density_g_cm3": rho, "settlement_param_mm": s_max, "erosion_rate_kg_m2_h": box_rate,
                     "interrill_rate_kg_m2_h": rate, "flow_shear_max_pa": tau_max, "critical_shear_pa": rn["critical_shear_pa"],
                     "upstream_minus_downstream_model_mm": (e_up - e_down) * rn["duration_min"] / 60.0 / (rho * 1e3) * 1e3,
                     "pairs": len(times), "M_s_final_mm": Ms[-1], "A_s_final_mm": As[-1],
                     "MAE_mm": mae(Ms, As), "MRE_pct": mre(Ms, As),
                     "MAE_paper_mm": PAPER["rain"].get(rho, (np.nan, np.nan))[0], "MRE_paper_pct": PAPER["rain"].get(rho, (np.nan, np.nan))[1],
                     "upstream_minus_downstream_mm": up_down, "upstream_minus_downstream_paper_mm": PAPER["upstream_minus_downstream_mm"],
                     **{f"first_pair_{k}": v for k, v in pair_columns(pp, truth, marks.xyz).items()}})
        log.info("rain ρ_b %.2f: MAE %.3f mm, MRE %.1f %%", rho, runs[-1]["MAE_mm"], runs[-1]["MRE_pct"])
    write_table(pd.DataFrame(runs), out["rain_runs"])
    write_table(pd.DataFrame(series), out["rain_series"])


# ----------------------------------------------------------------------------- rule: wind
def measure_wind(cfg: Mapping[str, Any], cameras_json: str, seed: int, out: Mapping[str, str]) -> None:
    """Rule ``stereo_wind``: the sand tray before and after 45 min of wind; MAE at the 20 nails and mean lowering.

    Parameters
    ----------
    cfg : mapping
        ``stereo.processing`` and ``stereo.wind``.
    cameras_json : str
    seed : int
    out : mapping
        ``wind_run`` (csv), ``dod_png``.
    """
    params = StereoParams.from_config(cfg)
    cams = _load_cameras(cameras_json)
    proc, wd = params.processing, params.wind
    H, B = float(wd["H_m"]), float(wd["B_m"])
    # the part of the 2.0 × 0.45 m tray both cameras see at H = 0.6 m: a 0.12 × 0.12 m patch of sand
    box = (-0.06, -0.06, 0.06, 0.06)
    # [I] sand texture at ~0.7 ground pixel (0.08 mm at H = 0.6 m), grains 2-50 cells
    cell = float(np.clip(H * D2H_PIXEL_MM / 51.4 / 1.4, 8e-5, 2.5e-4))
    sand = dict(cell_m=cell, scales_m=(2 * cell, 5 * cell, 15 * cell, 50 * cell))
    texture = soil_texture(rng_for(seed, "stereo", "texture_sand"), (-0.12, -0.12, 0.12, 0.12), **sand)
    lam, amp = wd["ripple_wavelength_mm"] * 1e-3, wd["ripple_mm"] * 1e-3
    defl = wd["deflation_mm"] * 1e-3

    def surface(after: bool):
        shift = 0.5 * lam if after else 0.0
        return lambda x, y: 0.5 * amp * np.sin(2 * np.pi * (x - shift) / lam + 0.3 * np.sin(2 * np.pi * y / 0.05)) - (defl if after else 0.0)

    rng = rng_for(seed, "stereo", "wind")
    truth = paper_rig(H, B)
    diameter = wd["mark_diameter_mm"] * 1e-3
    marks = PrintedMarks(frame_marks(box), MarkDesign(diameter))
    grid = box_grid(wd["cell_mm"] * 1e-3, box)
    extent = np.array([[x, y, z] for x in (box[0], box[2]) for y in (box[1], box[3]) for z in (-0.003, 0.003)])
    imgs0 = render_pair(truth, surface(False), texture, proc["image_noise_dn"], rng, extent, marks)
    pp = PairProcessor.from_images(cams, *imgs0, survey_marks(marks.xyz, rng, proc), diameter, B, H, MatchParams(**proc["matching"]))
    d0, _ = pp.dem(*imgs0, grid)
    texture1 = soil_texture(rng_for(seed, "stereo", "texture_sand_after"), (-0.12, -0.12, 0.12, 0.12), **sand)  # [I] new grains
    d1, _ = pp.dem(*render_pair(truth, surface(True), texture1, proc["image_noise_dn"], rng, extent, marks), grid)
    nails = nail_positions(rng, box)
    gauge_before = cell_truth(surface(False), grid)
    gauge_after = cell_truth(surface(True), grid)
    r, c = grid.index(nails[:, 0], nails[:, 1])
    ok = d0.valid[r, c] & d1.valid[r, c]
    M_i = (gauge_before - gauge_after)[r, c][ok] * 1e3 + rng.normal(0, 0.01, ok.sum())  # micrometer ±0.01 mm
    A_i = (d0.data - d1.data)[r, c][ok] * 1e3
    both = d0.valid & d1.valid
    S_cm2 = (box[2] - box[0]) * (box[3] - box[1]) * 1e4
    M_s = 10 * (wd["sand_density"] * defl * 1e2 * S_cm2) / (wd["sand_density"] * S_cm2)
    A_s = float(np.mean((d0.data - d1.data)[both])) * 1e3
    row = {"H_m": H, "B_m": B, "L_m": float(stereo_L_m(H, B)), "nails": int(ok.sum()), "MAE_nails_mm": mae(M_i, A_i),
           "M_s_mm": M_s, "A_s_mm": A_s, "surface_abs_error_mm": abs(A_s - M_s),
           "dod_mae_vs_gauge_mm": 1e3 * mae((gauge_before - gauge_after)[both], (d0.data - d1.data)[both]),
           "MAE_paper_mm": PAPER["wind_mae_mm"], **pair_columns(pp, truth, marks.xyz)}
    write_table(pd.DataFrame([row]), out["wind_run"])
    _dod_figure(d1.data - d0.data, grid, "Wind tunnel, 45 min at 4.5 m/s", out["dod_png"])
    log.info("wind: MAE at nails %.3f mm", row["MAE_nails_mm"])

