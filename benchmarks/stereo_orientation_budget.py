"""Stereo (paper 003): what the orientation and calibration add to the DEM error, without images.

With tie points and frame marks simulated at 0.2 px (sessions 6-9) the stage's surface MAE grew 3.6 ×
faster with L than the δz model at its matching precision; measured in the photographs (session 10)
it is 0.86 × (README "Plot-scale stereo"). This script isolates the
geometric part of the chain: points of the true soil surface are projected through the true
cameras into both photographs (exact matching) and processed by the stage's own
:class:`kitegully.stereo.processing.PairProcessor` (rectification from the estimated relative
orientation, triangulation, similarity on the 10 frame marks); their height error is the error a
perfect matcher would leave. Each error source is switched on alone:

* ``marks``: the 10 frame marks measured to ``mark_sigma_px`` and surveyed to ``mark_sigma_mm``;
* ``ties``: the tie points of the relative orientation (``n_ties`` on the soil surface, as SIFT finds
  them on the box) measured to ``tie_sigma_px`` (0.01 px otherwise);
* ``survey``: only the marks' survey error ``mark_sigma_mm`` (image measurement exact);
* ``calibration``: the cameras from ``cameras.json`` (the stage's calibration) instead of the truth;
* ``all``: everything, as in the stage.

For each source, MAE = a·L is fitted through the origin over ``trials`` draws per set-up. Last, the
spread of a DEM of difference between two pairs oriented on independent measurements of the frame
marks (``processing.reorient_each_pair``): its box mean and its upstream − downstream difference.

The image precisions are the ones the stage *measured* in its photographs (session 10: marks located by
template + weighted centroid, tie points by SIFT): by default the medians of ``mark_error_px``,
``tie_sampson_rms_px`` and ``ties_inliers`` over the 11 set-ups of ``mae_vs_L.csv``; ``--mark-px``,
``--tie-px``, ``--ties`` override them (e.g. the earlier assumption 0.2 px, 0.2 px, 300).

Usage: PYTHONPATH=src .venv/bin/python benchmarks/stereo_orientation_budget.py [--trials 8]
       [--cameras results/stereo_lab/stereo/cameras.json] [--mark-px 0.2 --tie-px 0.2 --ties 300]
Writes benchmarks/out/stereo_orientation_budget.md. One core, a few minutes (the relative orientation
adjusts every tie point).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import yaml

from kitegully.seeds import rng_for
from kitegully.stereo.matching import MatchParams
from kitegully.stereo.metrics import fit_mae_vs_L
from kitegully.stereo.rig import delta_z_m, paper_cameras, paper_rig, stereo_L_m
from kitegully.stereo.lab import BOX, box_grid, frame_marks, relief
from kitegully.stereo.processing import PairProcessor
from kitegully.stereo.stage import _load_cameras

REPO = Path(__file__).resolve().parents[1]


def geometric_mae_mm(H, B, cams, proc, rng, sources):
    """MAE (mm) of the heights of the true surface processed with exact matching; ``sources`` switches the errors."""
    truth = paper_rig(H, B)
    n = int(proc["n_ties"])
    # the ties lie where SIFT finds them: on the soil surface of the box (a nearly flat scene)
    tx, ty = rng.uniform(BOX[0], BOX[2], n), rng.uniform(BOX[1], BOX[3], n)
    tie = np.column_stack([tx, ty, relief(tx, ty)])
    # without the tie-point source the ties get 0.01 px (exactly noise-free ties can leave the RANSAC with < 5 inliers)
    st = proc["tie_sigma_px"] if "ties" in sources else 0.01
    sm = proc["mark_sigma_px"] if "marks" in sources else 0.0
    smm = proc["mark_sigma_mm"] if ("marks" in sources or "survey" in sources) else 0.0
    tl = truth.left.project(tie, truth.pose_left) + rng.normal(0, st, (n, 2))
    tr = truth.right.project(tie, truth.pose_right) + rng.normal(0, st, (n, 2))
    marks = frame_marks()
    ml = truth.left.project(marks, truth.pose_left) + rng.normal(0, sm, (10, 2))
    mr = truth.right.project(marks, truth.pose_right) + rng.normal(0, sm, (10, 2))
    surveyed = marks + rng.normal(0, smm * 1e-3, marks.shape)
    pp = PairProcessor(cams if "calibration" in sources else paper_cameras(), tl, tr, ml, mr, surveyed, B, H,
                       MatchParams(**proc["matching"]))
    grid = box_grid(proc["cell_mm"] * 1e-3)
    X, Y = np.meshgrid(*grid.cell_centres())
    P = np.column_stack([X.ravel(), Y.ravel(), relief(X.ravel(), Y.ravel())])
    Q = pp.points(truth.left.project(P, truth.pose_left), truth.right.project(P, truth.pose_right))
    return 1e3 * float(np.mean(np.abs(Q[:, 2] - P[:, 2])))


def _measure_marks(rig, marks, rng, sigma_px):
    """The frame marks' image positions with N(0, ``sigma_px``) per coordinate (the stage's measured precision)."""
    n = len(marks)
    return (rig.left.project(marks, rig.pose_left) + rng.normal(0, sigma_px, (n, 2)),
            rig.right.project(marks, rig.pose_right) + rng.normal(0, sigma_px, (n, 2)))


def reorientation_spread(H, B, proc, seed, draws=200, slope_deg=10.0):
    """Spread of a DoD between two pairs oriented on independent mark measurements (exact matching, true cameras).

    Returns the standard deviations (mm) over ``draws`` of the DoD's box mean and of its upstream − downstream
    half difference on the rain box (10°, halves along y of the central 80 %).
    """
    rng = rng_for(seed, "budget", "reorient", f"{H}-{B}")
    truth = paper_rig(H, B)
    tan = np.tan(np.radians(slope_deg))
    marks = frame_marks() + np.c_[np.zeros((10, 2)), -tan * frame_marks()[:, 1]]
    n = int(proc["n_ties"])
    tx, ty = rng.uniform(BOX[0], BOX[2], n), rng.uniform(BOX[1], BOX[3], n)
    tie = np.column_stack([tx, ty, -tan * ty + relief(tx, ty)])
    tl = truth.left.project(tie, truth.pose_left) + rng.normal(0, proc["tie_sigma_px"], (n, 2))
    tr = truth.right.project(tie, truth.pose_right) + rng.normal(0, proc["tie_sigma_px"], (n, 2))
    ml, mr = _measure_marks(truth, marks, rng, proc["mark_sigma_px"])
    pp = PairProcessor(paper_cameras(), tl, tr, ml, mr, marks + rng.normal(0, proc["mark_sigma_mm"] * 1e-3, marks.shape), B, H,
                       MatchParams(**proc["matching"]))
    grid = box_grid(proc["cell_mm"] * 1e-3)
    X, Y = np.meshgrid(*grid.cell_centres())
    P = np.column_stack([X.ravel(), Y.ravel(), -tan * Y.ravel()])
    ul, ur = truth.left.project(P, truth.pose_left), truth.right.project(P, truth.pose_right)
    z = [pp.reoriented(*_measure_marks(truth, marks, rng, proc["mark_sigma_px"])).points(ul, ur)[:, 2] for _ in range(draws + 1)]
    dod = np.diff(np.array(z), axis=0) * 1e3  # consecutive pairs: independent orientations
    up = P[:, 1] < 0
    return float(np.std(dod.mean(axis=1))), float(np.std(dod[:, up].mean(axis=1) - dod[:, ~up].mean(axis=1)))


FAILED_DRAWS = []


def _draw(H, B, cams, proc, seed, sources, t):
    """One draw; a draw whose relative orientation fails (recoverPose keeping < 5 of the near-exact ties) is redrawn and counted."""
    for k in range(5):
        try:
            return geometric_mae_mm(H, B, cams, proc, rng_for(seed, "budget", "+".join(sources), f"{H}-{B}", t, k), sources)
        except ValueError:
            FAILED_DRAWS.append((sources, H, B, t, k))
    raise RuntimeError(f"relative orientation failed 5 times at H {H} B {B}")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--trials", type=int, default=8)
    ap.add_argument("--cameras", default=str(REPO / "results/stereo_lab/stereo/cameras.json"))
    ap.add_argument("--seed", type=int, default=2010)
    ap.add_argument("--mae-vs-L", default=str(REPO / "results/stereo_lab/stereo/mae_vs_L.csv"),
                    help="the stage's table with the measured mark_error_px, tie_sampson_rms_px, ties_inliers")
    ap.add_argument("--mark-px", type=float, help="mark image precision (px); default: measured")
    ap.add_argument("--tie-px", type=float, help="tie point precision (px); default: measured")
    ap.add_argument("--ties", type=int, help="number of tie points; default: measured")
    a = ap.parse_args()
    cfg = yaml.safe_load((REPO / "config/sites/stereo_lab.yaml").read_text())["stereo"]
    proc, setups = dict(cfg["processing"]), [tuple(s) for s in cfg["dry_box"]["setups"]]
    if None in (a.mark_px, a.tie_px, a.ties):
        import pandas as pd
        mv = pd.read_csv(a.mae_vs_L)
    proc["mark_sigma_px"] = a.mark_px if a.mark_px is not None else float(mv["mark_error_px"].median())
    proc["tie_sigma_px"] = a.tie_px if a.tie_px is not None else float(mv["tie_sampson_rms_px"].median())
    proc["n_ties"] = a.ties if a.ties is not None else int(mv["ties_inliers"].median())
    cams = _load_cameras(a.cameras)
    L = np.array([float(stereo_L_m(H, B)) for H, B in setups])
    k = float(np.mean([delta_z_m(H, B, cams["left"]) * 1e3 / stereo_L_m(H, B) for H, B in setups]))
    lines = ["# Stereo: geometric error budget of the dry-box chain (exact matching)", "",
             f"{a.trials} draws per set-up, 11 set-ups; MAE = a·L through the origin. δz of 1 px = {k:.4f} mm per m of L.",
             f"Marks {proc['mark_sigma_px']:.4f} px, surveyed to {proc['mark_sigma_mm']} mm; {proc['n_ties']} tie points on the soil at "
             f"{proc['tie_sigma_px']:.3f} px.", "",
             "| error source | a (mm per m of L) | R² | equivalent disparity error √(π/2)·a/(δz per px) (px) |", "|---|---|---|---|"]
    for sources in (("marks",), ("survey",), ("ties",), ("calibration",), ("marks", "ties", "calibration")):
        m = np.array([[_draw(H, B, cams, proc, a.seed, sources, t) for t in range(a.trials)] for H, B in setups])
        aa, r2 = fit_mae_vs_L(L, m.mean(axis=1))
        label = "all (as in the stage)" if len(sources) == 3 else sources[0]
        lines.append(f"| {label} | {aa:.4f} | {r2:.2f} | {np.sqrt(np.pi / 2) * aa / k:.3f} |")
        print(lines[-1], flush=True)
    lines += ["", f"Redrawn after a failed relative orientation: {len(FAILED_DRAWS)} draws."]
    sm, sud = reorientation_spread(2.7, 0.8, proc, a.seed)
    lines += ["", f"Two pairs at L = 9.1 m (H 2.7, B 0.8) oriented on independent measurements of the 10 frame marks "
              f"({proc['mark_sigma_px']:.4g} px, exact matching): DoD box mean σ = {sm:.3f} mm (MAE √(2/π)·σ = {np.sqrt(2 / np.pi) * sm:.3f} mm), "
              f"upstream − downstream half difference on the 10° box σ = {sud:.3f} mm."]
    out = REPO / "benchmarks" / "out"
    out.mkdir(parents=True, exist_ok=True)
    (out / "stereo_orientation_budget.md").write_text("\n".join(lines) + "\n", encoding="utf-8")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
