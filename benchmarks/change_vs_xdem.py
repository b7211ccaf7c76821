"""Our change stage against xDEM on the DEM-site example: co-registration and volume uncertainty.

xDEM cannot go into the project venv (it would downgrade pandas 3), so this script builds a
throwaway venv ``.venv-xdem`` with pip (network needed, a few minutes the first time) and
runs xDEM there on the same inputs our ``change_detect`` rule used:

* co-registration: ``xdem.coreg.NuthKaab() + xdem.coreg.Deramp(poly_order=1)`` on our
  stable-ground mask (``results/<site>/change/stable_ground.tif``), against our
  ``coregistration.csv`` (shift, offset, tilt, stable-ground NMAD after);
* volume uncertainty: ``xdem.spatialstats.infer_spatial_correlation_from_stable`` +
  ``neff_circular_approx_numerical`` for the whole site, against our
  ``net_sd_correlated_m3`` of the site row in ``budget.csv``;
* wall time of each.

Run the change stage first (``snakemake --configfile config/sites/kamech_dem_change.yaml``),
then: ``.venv/bin/python benchmarks/change_vs_xdem.py [--site kamech_dem_change]``.
Writes ``benchmarks/out/change_vs_xdem.md``. Not run in the test suite (network, minutes).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import venv
from pathlib import Path

import pandas as pd
import yaml

REPO = Path(__file__).resolve().parents[1]
XVENV = REPO / ".venv-xdem"

CHILD = r"""
import json, sys, time
import numpy as np, geoutils as gu, xdem
a = json.loads(sys.argv[1])
ref = xdem.DEM(a["dem1"]); tba = xdem.DEM(a["dem2"]).reproject(ref)
stable = gu.Raster(a["stable"]).reproject(ref).data.filled(0).astype(bool)
t0 = time.perf_counter()
pipe = xdem.coreg.NuthKaab() + xdem.coreg.Deramp(poly_order=1)
pipe.fit(ref, tba, inlier_mask=stable)
aligned = pipe.apply(tba)
t_coreg = time.perf_counter() - t0
dh = aligned - ref
d = dh.data.filled(np.nan)[stable]
d = d[np.isfinite(d)]
m = np.asarray(pipe.pipeline[0].to_matrix())  # 4 x 4 affine of the Nuth & Kaab step
out = dict(coreg_s=t_coreg, shift_x=float(m[0, 3]), shift_y=float(m[1, 3]), shift_z=float(m[2, 3]),
           nmad_after=float(1.4826 * np.median(np.abs(d - np.median(d)))), median_after=float(np.median(d)))
t0 = time.perf_counter()
sigma = float(a["sigma_dod"])
z = dh / sigma
df_emp, df_model, _ = xdem.spatialstats.infer_spatial_correlation_from_stable(
    z, stable_mask=stable, list_models=["Spherical", "Spherical"], random_state=42, subsample=2000)
area = float(a["area_m2"])
neff = xdem.spatialstats.neff_circular_approx_numerical(area=area, params_variogram_model=df_model)
out.update(variogram_s=time.perf_counter() - t0, net_sd_m3=float(sigma / np.sqrt(neff) * area),
           variogram_model=df_model.to_dict(orient="records"))
print("RESULT" + json.dumps(out, default=str))
"""


def ensure_venv() -> Path:
    py = XVENV / "bin" / "python"
    if not py.exists():
        print(f"creating {XVENV} and installing xdem with pip (network, minutes)")
        venv.create(XVENV, with_pip=True)
        subprocess.run([str(py), "-m", "pip", "install", "-q", "xdem"], check=True)
    return py


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--site", default="kamech_dem_change")
    a = ap.parse_args()
    cfg = yaml.safe_load((REPO / "config" / "sites" / f"{a.site}.yaml").read_text())
    res = REPO / "results" / a.site / "change"
    ours_c = pd.read_csv(res / "coregistration.csv").set_index("quantity")["value"]
    bud = pd.read_csv(res / "budget.csv")
    site = bud[(bud["mask"] == "site") & (bud["method"] == "raw")].iloc[0]
    sig = pd.read_csv(res / "sigma.csv").set_index("epoch").loc["DoD", "sigma_m"]
    args = dict(dem1=str(REPO / cfg["change"]["epochs"][0]["dem"]), dem2=str(REPO / cfg["change"]["epochs"][1]["dem"]),
                stable=str(res / "stable_ground.tif"), sigma_dod=float(sig), area_m2=float(site["area_m2"]))
    py = ensure_venv()
    p = subprocess.run([str(py), "-c", CHILD, json.dumps(args)], capture_output=True, text=True, cwd=REPO)
    if p.returncode != 0:
        sys.exit(p.stderr[-3000:])
    x = json.loads(p.stdout.split("RESULT", 1)[1])
    # sign conventions differ: ours is the shift of DEM2's features (DEM2 corrected = DEM2(x + d)),
    # xDEM's matrix moves DEM2 onto DEM1, so expect the opposite sign
    rows = [("shift x (m)", ours_c.get("dx"), x.get("shift_x")), ("shift y (m)", ours_c.get("dy"), x.get("shift_y")),
            ("stable NMAD after (m)", ours_c.get("stable_nmad_after"), x["nmad_after"]),
            ("stable median after (m)", ours_c.get("stable_median_after"), x["median_after"]),
            ("site net SD, correlated (m3)", site["net_sd_correlated_m3"], x["net_sd_m3"]),
            ("xDEM co-registration time (s)", None, x["coreg_s"]), ("xDEM variogram time (s)", None, x["variogram_s"])]
    table = pd.DataFrame(rows, columns=["quantity", "kitegully", "xdem"])
    out = REPO / "benchmarks" / "out"
    out.mkdir(parents=True, exist_ok=True)
    (out / "change_vs_xdem.md").write_text(table.to_markdown(index=False) + "\n\nxDEM variogram model: "
                                           + json.dumps(x["variogram_model"], default=str) + "\n", encoding="utf-8")
    print(table.to_string(index=False))


if __name__ == "__main__":
    main()
