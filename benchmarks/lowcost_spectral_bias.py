"""Is the red/NIR peak bias of the spectral-response recovery the chart or the method? (issue 18)

Recovers the RGB + NIR-converted responses from simulated ColorChecker shots under
variations that separate the causes, and writes results/benchmarks/lowcost_spectral_bias.csv
(+ .md): peak error (recovered - true, nm) per channel, mean and worst over the draws.

  - noise-free data with a fixed small smoothness weight (does the chart hold the information?);
  - the stage's method (second differences, discrepancy principle) at 0.5 %, 0.1 % and 0.02 % noise;
  - a first-difference penalty, and the discrepancy level at the expected misfit instead of 95 %;
  - a 2.5 nm wavelength grid;
  - a chart of 24 + 200 random smooth spectra (more panels, same noise).

Run: PYTHONPATH=src python benchmarks/lowcost_spectral_bias.py   (about 2 min on one core)
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
    main()
