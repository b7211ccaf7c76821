"""Our change stage against xDEM on the same DEM pair: co-registration shift, DoD volume, speed.

xDEM cannot go into the project venv (it would downgrade pandas 3), so this script builds a
throwaway venv ``.venv-xdem`` with pip (PyPI, pinned ``xdem==XDEM_VERSION`` and its optional ``scikit-gstat``; network, a few
minutes the first time) and runs xDEM there on the same inputs as our ``change_detect`` rule:

* the same two DEM files and our stable-ground mask (``results/<site>/change/stable_ground.tif``);
* co-registration: ours (:func:`kitegully.change.coregister.coregister`, Nuth & Kääb shift +
  plane, run here in this process and timed) against ``xdem.coreg.NuthKaab()`` alone and
  ``NuthKaab() + Deramp(poly_order=1)`` (xDEM's equivalent of our shift + plane), each timed
  (fit + apply);
* the DoD and its whole-site net volume Σ dh·a over the same cells (our DoD's valid cells,
  i.e. without our low-correlation voids), and the stable-ground median/NMAD after;
* the correlated net SD from xDEM's variogram (``infer_spatial_correlation_from_stable`` +
  ``neff_circular_approx_numerical``) against our ``net_sd_correlated_m3``.

Sign conventions: ours is the shift of DEM₂'s features (DEM₂ corrected = DEM₂(x + Δ));
xDEM's matrix translates DEM₂ onto DEM₁, so equal shifts show with opposite signs.

Run the change stage of the site first, then ``make change-vs-xdem`` (or
``.venv/bin/python benchmarks/change_vs_xdem.py --site kamech_dem_change``).
Writes ``benchmarks/out/change_vs_xdem.md`` and ``.json``. Not in the test suite (network, minutes).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
import venv
from pathlib import Path

import numpy as np
import pandas as pd
import yaml

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "src"))
XVENV = REPO / ".venv-xdem"
XDEM_VERSION = "0.2.3"
SKGSTAT_VERSION = "1.0.26"  # xDEM's optional variogram dependency (scikit-gstat)

CHILD = r"""
import json, sys, time, warnings
warnings.filterwarnings("ignore")
import numpy as np, geoutils as gu, xdem
a = json.loads(sys.argv[1])
ref = xdem.DEM(a["dem1"]); tba = xdem.DEM(a["dem2"]).reproject(ref)
stable = gu.Raster(a["stable"]).reproject(ref).data.filled(0).astype(bool)
counted = gu.Raster(a["counted"]).reproject(ref).data.filled(0).astype(bool)
cell = float(ref.res[0])
out = {"xdem_version": xdem.__version__}
def stats(aligned, key):
    dh = (aligned - ref).data.filled(np.nan)
    d = dh[stable]; d = d[np.isfinite(d)]
    ok = counted & np.isfinite(dh)
    out[key] = dict(median_after=float(np.median(d)), nmad_after=float(1.4826 * np.median(np.abs(d - np.median(d)))),
                    net_m3=float(np.sum(dh[ok]) * cell * cell), cells=int(ok.sum()))
    return dh
for key, make in (("nk", lambda: xdem.coreg.NuthKaab()), ("nk_deramp", lambda: xdem.coreg.NuthKaab() + xdem.coreg.Deramp(poly_order=1))):
    c = make()
    t0 = time.perf_counter()
    c.fit(ref, tba, inlier_mask=stable)
    aligned = c.apply(tba)
    t = time.perf_counter() - t0
    first = c.pipeline[0] if hasattr(c, "pipeline") else c
    m = np.asarray(first.to_matrix())
    dh = stats(aligned, key)
    out[key].update(seconds=t, shift_x=float(m[0, 3]), shift_y=float(m[1, 3]), shift_z=float(m[2, 3]))
t0 = time.perf_counter()
sigma = float(a["sigma_dod"])
z = (dh / sigma).astype("float32")
z[~stable] = np.nan
df_emp, df_model, _ = xdem.spatialstats.infer_spatial_correlation_from_stable(
    z, list_models=["Spherical", "Spherical"], gsd=cell, random_state=42, subsample=2000)
area = float(a["area_m2"])
neff = xdem.spatialstats.neff_circular_approx_numerical(area=area, params_variogram_model=df_model)
out.update(variogram_s=time.perf_counter() - t0, net_sd_correlated_m3=float(sigma / np.sqrt(neff) * area),
           variogram_model=df_model.to_dict(orient="records"))
print("RESULT" + json.dumps(out, default=str))
"""


def ensure_venv() -> Path:
    """``.venv-xdem`` with xDEM pinned (created once with pip from PyPI)."""
    py = XVENV / "bin" / "python"
    if not py.exists():
        print(f"creating {XVENV} and installing xdem=={XDEM_VERSION} with pip (network, minutes)", flush=True)
        venv.create(XVENV, with_pip=True)
    pins = [f"xdem=={XDEM_VERSION}", f"scikit-gstat=={SKGSTAT_VERSION}"]
    have = subprocess.run([str(py), "-m", "pip", "freeze"], capture_output=True, text=True).stdout.lower()
    if not all(p.lower() in have for p in pins):
        subprocess.run([str(py), "-m", "pip", "install", "-q", *pins], check=True)
    return py


def ours(cfg: dict, res: Path) -> dict:
    """Our co-registration on the same inputs, timed; net over our DoD's valid cells."""
    from kitegully.change.coregister import coregister
    from kitegully.evaluate.dem import nmad
    from kitegully.change.dod import load_epoch, on_common_grid
    from kitegully.change.params import ChangeParams
    from kitegully.io.raster import Raster

    ch = cfg["change"]
    e1, e2 = (load_epoch(s, f"change.epochs[{i}]") for i, s in enumerate(ch["epochs"]))
    grid, z1, _ = on_common_grid(e1, e2)
    stable = Raster.read(res / "stable_ground.tif").data == 1
    params = ChangeParams.from_config({k: ch[k] for k in ("coregistration", "thresholds", "budget", "headcuts")}, seed=cfg["seed"])
    t0 = time.perf_counter()
    z2, info = coregister(z1, e2.dem, grid, stable, params)
    t = time.perf_counter() - t0
    dod = Raster.read(res / "dod.tif").data
    ok = np.isfinite(dod)
    d = (z2 - z1)[stable & np.isfinite(z2) & np.isfinite(z1)]
    return dict(seconds=t, shift_x=info.dx_m, shift_y=info.dy_m, dz_centre=info.dz_m, median_after=float(np.median(d)),
                nmad_after=nmad(d), net_m3=float(np.nansum(dod[ok]) * grid.cell**2), cells=int(ok.sum()))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--site", default="kamech_dem_change")
    a = ap.parse_args()
    cfg = yaml.safe_load((REPO / "config" / "sites" / f"{a.site}.yaml").read_text())
    if cfg["change"]["epochs"] is None:
        sys.exit(f"{a.site}: change.epochs is null (a twin); use a DEM site such as kamech_dem_change")
    res = REPO / "results" / a.site / "change"
    bud = pd.read_csv(res / "budget.csv")
    site = bud[(bud["mask"] == "site") & (bud["method"] == "raw")].iloc[0]
    sig = pd.read_csv(res / "sigma.csv").set_index("epoch").loc["DoD", "sigma_m"]
    from kitegully.io.raster import Raster
    dod = Raster.read(res / "dod.tif")
    counted = res.parent / "xdem_counted.tif"
    Raster(np.isfinite(dod.data).astype(np.uint8), dod.grid, 255).write(counted)
    args = dict(dem1=str(REPO / cfg["change"]["epochs"][0]["dem"]), dem2=str(REPO / cfg["change"]["epochs"][1]["dem"]),
                stable=str(res / "stable_ground.tif"), counted=str(counted), sigma_dod=float(sig), area_m2=float(site["area_m2"]))
    py = ensure_venv()
    me = ours(cfg, res)
    p = subprocess.run([str(py), "-c", CHILD, json.dumps(args)], capture_output=True, text=True, cwd=REPO)
    if p.returncode != 0:
        sys.exit(p.stderr[-3000:])
    x = json.loads(p.stdout.split("RESULT", 1)[1])
    nk, nd = x["nk"], x["nk_deramp"]
    rows = [
        ("shift x (m; xDEM sign flipped)", me["shift_x"], -nk["shift_x"], -nd["shift_x"]),
        ("shift y (m; xDEM sign flipped)", me["shift_y"], -nk["shift_y"], -nd["shift_y"]),
        ("vertical shift of the shift step (m)", me["dz_centre"], -nk["shift_z"], -nd["shift_z"]),
        ("stable median after (m)", me["median_after"], nk["median_after"], nd["median_after"]),
        ("stable NMAD after (m)", me["nmad_after"], nk["nmad_after"], nd["nmad_after"]),
        ("site net volume, same cells (m3)", me["net_m3"], nk["net_m3"], nd["net_m3"]),
        ("co-registration wall time, fit + apply (s)", me["seconds"], nk["seconds"], nd["seconds"]),
        ("site net SD, correlated (m3)", float(site["net_sd_correlated_m3"]), x["net_sd_correlated_m3"], np.nan),
        ("variogram wall time (s)", np.nan, x["variogram_s"], np.nan),
    ]
    table = pd.DataFrame(rows, columns=["quantity", "kitegully", f"xDEM {x['xdem_version']} NuthKaab",
                                        "xDEM NuthKaab + Deramp(1)"])
    out = REPO / "benchmarks" / "out"
    out.mkdir(parents=True, exist_ok=True)
    (out / "change_vs_xdem.md").write_text(
        f"Site {a.site}, {me['cells']} counted cells.\n\n" + table.to_markdown(index=False, floatfmt=".4g")
        + "\n\nxDEM variogram model: " + json.dumps(x["variogram_model"], default=str) + "\n", encoding="utf-8")
    (out / "change_vs_xdem.json").write_text(json.dumps(dict(ours=me, xdem=x), indent=1, default=str), encoding="utf-8")
    print(table.to_string(index=False))


if __name__ == "__main__":
    main()
