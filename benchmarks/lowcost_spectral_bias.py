"""Is the red/NIR peak bias of the spectral-response recovery the chart or the method? (issue 18)

Recovers the RGB + NIR-converted responses from simulated ColorChecker shots under
variations that separate the causes, and writes results/benchmarks/lowcost_spectral_bias.csv
(+ .md): peak error (recovered - true, nm) per channel, mean and worst over the draws.

  - noise-free data with a fixed small smoothness weight (does the chart hold the information?);
  - the stage's method (second differences, discrepancy principle) at 0.5 %, 0.1 % and 0.02 % noise;
  - a first-difference penalty, and the discrepancy level at the expected misfit instead of 95 %;
  - a 2.5 nm wavelength grid;
  - a chart of 24 + 200 random smooth spectra (more panels, same noise).

A second table, results/benchmarks/lowcost_spectral_designs.csv (+ .md), compares ways to
choose the smoothness weight on the paper's single sunlit shot (the stage's discrepancy
principle; UPRE, i.e. Mallows' C_p with the stated noise; GCV; the L-curve corner) with
calibration designs that add data (frames averaged per shot; shots under illuminant A
and the triband fluorescent FL11), 20 draws each as the stage: peak error mean and worst
(nm) and the curve RMS error per channel. The site uses D65 + A + FL11 with 16 frames.

Run: PYTHONPATH=src python benchmarks/lowcost_spectral_bias.py   (about 6 min on one core)
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
from scipy.ndimage import gaussian_filter1d
from scipy.optimize import nnls

from kitegully.io.tables import write_table
from kitegully.lowcost import spectral as sp
from kitegully.seeds import rng_for

DRAWS = 6
NAMES = ["red", "green", "blue", "nir"]


def _first_difference(n):
    d = np.zeros((n - 1, n))
    i = np.arange(n - 1)
    d[i, i], d[i, i + 1] = -1.0, 1.0
    return d


def _recover_with(A, V, sigma, D, factor, lambdas):
    """The stage's recovery with another penalty matrix D and discrepancy factor."""
    An = A / np.linalg.norm(A, 2)
    out = []
    for c in range(V.shape[1]):
        v = V[:, c] / np.abs(V[:, c]).max()
        best = None
        for lam in np.sort(lambdas):
            s, _ = nnls(np.vstack([An, lam * D]), np.concatenate([v, np.zeros(D.shape[0])]), maxiter=5000)
            if best is None or np.sqrt(np.mean((An @ s - v) ** 2)) <= sigma * factor:
                best = s
        out.append(best / best.max())
    return np.array(out).T


def case(label, step=5.0, noise=0.005, extra_panels=0, recover=None):
    p = sp.SpectralParams(wl_step_nm=step)
    w = p.wavelengths
    _, refl = sp.chart_reflectance(w)
    if extra_panels:
        rng = np.random.default_rng(1)
        rich = np.clip(gaussian_filter1d(rng.random((extra_panels, len(w))), 4 * 5.0 / step, axis=1) * 1.5 - 0.2, 0.02, 1)
        refl = np.vstack([refl, rich])
    A = sp.chart_design(refl, sp.illuminant(p.illuminant, w), step)
    true = np.column_stack([sp.rgb_response(w), sp.nir_converted_response(w)])
    tp = sp.peak_wavelength(w, true)
    errs = []
    for d in range(DRAWS if noise > 0 else 1):
        V = sp.simulate_chart_shot(A, true, noise, rng_for(2013, "lowcost", "chart", d)) if noise > 0 else A @ true
        rec = recover(A, V, max(noise, 1e-9), p) if recover else sp.recover_response(A, V, noise, p.lambdas)[0]
        errs.append(sp.peak_wavelength(w, rec) - tp)
    e = np.array(errs)
    row = {"case": label}
    for i, n in enumerate(NAMES):
        row[f"{n}_mean_nm"] = e[:, i].mean()
        row[f"{n}_worst_nm"] = np.abs(e[:, i]).max()
    print(row, flush=True)
    return row


def _trace_hat(An, D, s, lam):
    """Trace of the influence matrix of the smooth NNLS on its free (positive) set."""
    F = s > 1e-12
    Af, Df = An[:, F], D[:, F]
    return float(np.trace(Af @ np.linalg.solve(Af.T @ Af + lam * lam * Df.T @ Df, Af.T)))


def _recover_rule(A3, V, sigma, lambdas, rule):
    """Smooth NNLS with the weight chosen by ``rule``: upre, gcv or lcurve."""
    D = sp._second_difference(A3.shape[2])
    out = []
    for c in range(V.shape[1]):
        An = A3[c] / np.linalg.norm(A3[c], 2)
        v = V[:, c] / np.abs(V[:, c]).max()
        n = len(v)
        sols = []
        for lam in np.sort(lambdas):
            s = sp._nnls_smooth(An, v, D, lam)
            sols.append((s, float(np.sum((An @ s - v) ** 2)), _trace_hat(An, D, s, lam), float(np.sum((D @ s) ** 2))))
        if rule == "upre":
            k = int(np.argmin([r2 + 2 * sigma ** 2 * t for _, r2, t, _ in sols]))
        elif rule == "gcv":
            k = int(np.argmin([r2 / (n - t) ** 2 for _, r2, t, _ in sols]))
        else:  # L-curve: corner of largest curvature of (log misfit, log roughness)
            x, y = np.log([r2 for _, r2, _, _ in sols]), np.log([g + 1e-300 for *_, g in sols])
            dx, dy = np.gradient(x), np.gradient(y)
            kap = (dx * np.gradient(dy) - np.gradient(dx) * dy) / (dx * dx + dy * dy) ** 1.5
            k = int(np.argmax(kap[2:-2])) + 2
        s = sols[k][0]
        out.append(s / s.max())
    return np.array(out).T


def design_case(label, illuminants=("D65",), frames=1, rule="discrepancy", draws=20):
    """Peak and curve errors of one calibration design and weight rule over ``draws`` draws."""
    p = sp.SpectralParams(illuminants=tuple(illuminants), frames_per_shot=frames)
    w = p.wavelengths
    _, refl = sp.chart_reflectance(w)
    designs = [sp.chart_design(refl, sp.illuminant(i, w), p.wl_step_nm) for i in p.illuminants]
    true = np.column_stack([sp.rgb_response(w), sp.nir_converted_response(w)])
    tp = sp.peak_wavelength(w, true)
    pk, ce = [], []
    for d in range(draws):
        shots = [sp.simulate_averaged_shot(A, true, p.relative_noise, frames, rng_for(2013, "lowcost", "chart", d, i))
                 for i, A in zip(p.illuminants, designs)]
        A3, V = sp.stack_shots(designs, shots)
        rec = (sp.recover_response(A3, V, p.shot_noise, p.lambdas)[0] if rule == "discrepancy"
               else _recover_rule(A3, V, p.shot_noise, p.lambdas, rule))
        pk.append(sp.peak_wavelength(w, rec) - tp)
        ce.append(sp.curve_error(true, rec))
    pk, ce = np.array(pk), np.array(ce)
    row = {"design": label, "weight_rule": rule}
    for i, n in enumerate(NAMES):
        row[f"{n}_mean_nm"] = pk[:, i].mean()
        row[f"{n}_worst_nm"] = np.abs(pk[:, i]).max()
    for i, n in enumerate(NAMES):
        row[f"{n}_curve_rms"] = ce[:, i].mean()
    print(row, flush=True)
    return row


def designs_table():
    rows = [design_case("D65, 1 frame (paper)")]
    rows += [design_case("D65, 1 frame (paper)", rule=r) for r in ("upre", "gcv", "lcurve")]
    rows += [
        design_case("D65, 16 frames", frames=16),
        design_case("D65 + A, 16 frames", ("D65", "A"), 16),
        design_case("D65 + FL11, 1 frame", ("D65", "FL11")),
        design_case("D65 + A + FL11, 1 frame", ("D65", "A", "FL11")),
        design_case("D65 + A + FL11, 16 frames (site)", ("D65", "A", "FL11"), 16),
        design_case("D65 + A + FL11, 16 frames (site)", ("D65", "A", "FL11"), 16, rule="upre"),
    ]
    out = Path(__file__).resolve().parents[1] / "results" / "benchmarks" / "lowcost_spectral_designs.csv"
    out.parent.mkdir(parents=True, exist_ok=True)
    write_table(pd.DataFrame(rows), out, floatfmt=".3g")
    print(f"wrote {out}")


def main():
    from scipy.stats import chi2
    f95 = np.sqrt(chi2.ppf(0.95, 24) / 24)
    rows = [
        case("noise-free, fixed weight 1e-4", noise=0.0, recover=lambda A, V, s, p: sp.recover_response(A, V, 1e-9, [1e-4])[0]),
        case("noise-free, fixed weight 1e-2", noise=0.0, recover=lambda A, V, s, p: sp.recover_response(A, V, 1e-9, [1e-2])[0]),
        case("stage method, 0.5 % noise"),
        case("stage method, 0.1 % noise", noise=0.001),
        case("stage method, 0.02 % noise", noise=0.0002),
        case("first differences, 0.5 %", recover=lambda A, V, s, p: _recover_with(A, V, s, _first_difference(A.shape[1]), f95, p.lambdas)),
        case("discrepancy at the expected misfit, 0.5 %", recover=lambda A, V, s, p: _recover_with(A, V, s, sp._second_difference(A.shape[1]), 1.0, p.lambdas)),
        case("2.5 nm grid, 0.5 %", step=2.5),
        case("24 + 200 smooth panels, 0.5 %", extra_panels=200),
    ]
    out = Path(__file__).resolve().parents[1] / "results" / "benchmarks" / "lowcost_spectral_bias.csv"
    out.parent.mkdir(parents=True, exist_ok=True)
    write_table(pd.DataFrame(rows), out, floatfmt=".1f")
    print(f"wrote {out}")


if __name__ == "__main__":
    import sys
    if "--designs-only" not in sys.argv:
        main()
    designs_table()
