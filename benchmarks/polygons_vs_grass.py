#!/usr/bin/env python
"""Breakline curvature and TCI of the polygons stage against GRASS GIS (issue 16).

On the stage DEM (``results/<site>/polygons/dem.tif``, 0.5 m) this compares

1. our Wood quadratic (least-squares kernels, 9 x 9) with ``r.param.scale size=9`` for the
   maximum (``maxic``) and plan (``planc``) curvature: correlation, slope of a robust fit,
   sign, and the agreement (IoU) of the breakline masks above the site's threshold;
2. our TCI = ln(a / tan β) (MFD, Freeman exponent, a in m²/m) with ``r.watershed tci=``
   (GRASS MFD, convergence 5): correlation and IoU of the thalweg masks above the site's
   TCI threshold;

and times both. GRASS is Debian ``grass-core`` (installed here with apt-get when missing;
skipped with a message if apt is unavailable).

Usage::

    .venv/bin/python benchmarks/polygons_vs_grass.py --dem results/kamech_twin/polygons/dem.tif

Results are printed and written to ``results/benchmarks/polygons_vs_grass.md``.
"""

from __future__ import annotations

import argparse
import subprocess
import tempfile
import textwrap
import time
from pathlib import Path

import numpy as np
import rasterio

from kitegully.config import load_yaml
from kitegully.io.raster import Raster
from kitegully.polygons.breaklines import convexity
from kitegully.polygons.thalweg import topographic_convergence_index

from gully_benchmark import ensure_grass  # noqa: E402  (benchmarks/ is the script's folder)

REPO = Path(__file__).resolve().parents[1]


def run_grass(grass: str, tif: Path, crs: str, work: Path, window: int) -> dict[str, tuple[float, np.ndarray]]:
    """r.param.scale (maxic, planc) and r.watershed (tci) on ``tif``; (seconds, array) per product."""
    script = work / "grass.sh"
    outs = {k: work / f"{k}.tif" for k in ("maxic", "planc", "tci")}
    script.write_text(textwrap.dedent(f"""\
        set -e
        r.in.gdal -o input={tif} output=dem --quiet
        g.region raster=dem
        t0=$(date +%s.%N); r.param.scale input=dem output=maxic size={window} method=maxic --quiet; t1=$(date +%s.%N)
        echo "TIME maxic $t0 $t1"
        t0=$(date +%s.%N); r.param.scale input=dem output=planc size={window} method=planc --quiet; t1=$(date +%s.%N)
        echo "TIME planc $t0 $t1"
        t0=$(date +%s.%N); r.watershed -a elevation=dem tci=tci --quiet; t1=$(date +%s.%N)
        echo "TIME tci $t0 $t1"
        for k in maxic planc tci; do r.out.gdal input=$k output={work}/$k.tif type=Float64 --quiet; done
        """))
    p = subprocess.run([grass, "--tmp-location", crs, "--exec", "bash", str(script)], capture_output=True, text=True)
    if p.returncode != 0:
        raise RuntimeError(f"GRASS failed: {p.stderr.strip()[-800:]}")
    times = {ln.split()[1]: float(ln.split()[3]) - float(ln.split()[2]) for ln in p.stdout.splitlines() if ln.startswith("TIME")}
    res = {}
    for k, path in outs.items():
        with rasterio.open(path) as src:
            a = src.read(1).astype(np.float64)
            if src.nodata is not None:
                a[a == src.nodata] = np.nan
        res[k] = (times[k], a)
    return res


def compare(ours: np.ndarray, theirs: np.ndarray, thr: float | None) -> dict[str, float]:
    """Correlation, robust slope (theirs ~ slope x ours) and IoU of the masks above ``thr``."""
    ok = np.isfinite(ours) & np.isfinite(theirs)
    a, b = ours[ok], theirs[ok]
    out = {"cells": int(ok.sum()), "pearson_r": float(np.corrcoef(a, b)[0, 1])}
    big = np.abs(a) > np.percentile(np.abs(a), 90)
    out["slope"] = float(np.median(b[big] / np.where(a[big] == 0, np.nan, a[big])))
    if thr is not None:
        ma, mb = a > thr, b > thr
        out["iou"] = float((ma & mb).sum() / max((ma | mb).sum(), 1))
        out["share_ours_pct"] = 100.0 * ma.mean()
        out["share_grass_pct"] = 100.0 * mb.mean()
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--dem", default=str(REPO / "results" / "kamech_twin" / "polygons" / "dem.tif"))
    ap.add_argument("--site", default=str(REPO / "config" / "sites" / "kamech_twin.yaml"))
    ap.add_argument("--out", default=str(REPO / "results" / "benchmarks" / "polygons_vs_grass.md"))
    args = ap.parse_args()
    cfg = load_yaml(args.site)["polygons"]
    window = cfg["breaklines"]["window_cells"]
    kthr = cfg["breaklines"]["threshold_per_m"]
    tthr = cfg["thalweg"]["tci_threshold"]
    dem = Raster.read(args.dem)
    z = dem.data.astype(np.float64)
    lines = [f"# Polygons stage vs GRASS GIS on {args.dem} ({dem.grid.height} x {dem.grid.width} cells of {dem.cell} m)", ""]
    t0 = time.perf_counter()
    kmax = convexity(z, dem.cell, window, "maximum")
    t_kmax = time.perf_counter() - t0
    t0 = time.perf_counter()
    kplan = convexity(z, dem.cell, window, "plan")
    t_kplan = time.perf_counter() - t0
    t0 = time.perf_counter()
    tci, _ = topographic_convergence_index(z, dem.cell, cfg["thalweg"]["mfd_exponent"], cfg["thalweg"]["min_tan_slope"])
    t_tci = time.perf_counter() - t0
    grass = ensure_grass()
    if grass is None:
        lines.append("GRASS not available: only our timings below.")
        g = {}
    else:
        with tempfile.TemporaryDirectory() as tmp:
            g = run_grass(grass, Path(args.dem), dem.crs, Path(tmp), window)
    lines += ["| product | ours (s) | GRASS (s) | cells | Pearson r | slope GRASS/ours | IoU of masks | ours above (%) | GRASS above (%) |",
              "|---|---|---|---|---|---|---|---|---|"]
    for name, ours, t_o, key, thr in (("maximum curvature (maxic), > %g 1/m" % kthr, kmax, t_kmax, "maxic", kthr),
                                      ("plan curvature (ours = -planc)", kplan, t_kplan, "planc", None),
                                      ("TCI, > %g" % tthr, tci, t_tci, "tci", tthr)):
        if key in g:
            t_g, theirs = g[key]
            if key == "planc":
                theirs = -theirs
            c = compare(ours, theirs, thr)
            lines.append(f"| {name} | {t_o:.2f} | {t_g:.2f} | {c['cells']} | {c['pearson_r']:.3f} | {c['slope']:.3f} | "
                         f"{c.get('iou', float('nan')):.3f} | {c.get('share_ours_pct', float('nan')):.2f} | {c.get('share_grass_pct', float('nan')):.2f} |")
        else:
            lines.append(f"| {name} | {t_o:.2f} | - | - | - | - | - | - | - |")
    text = "\n".join(lines) + "\n"
    print(text)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(text, encoding="utf-8")


if __name__ == "__main__":
    main()
