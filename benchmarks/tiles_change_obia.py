"""Tiled against untiled change stage and kite-scale OBIA map on a stored run (issue 21).

Reads a finished default-twin run (both epochs' dense DSMs, correlation, checkpoints, the
gully polygons, the kite bare-soil map, heads and cross-sections: the change stage's
inputs; the epoch-1 orthophoto and DSM: the kite map's), runs the untiled library calls
(``detect_change``, ``bare_soil_map``) and the tiled steps (the rules' library calls, one
process per job, in sequence) with ``tiling.tile_m`` over the site's extent, and writes
``<out>/tiles_benchmark.csv``: per job wall time, CPU time and peak RSS, plus the equality
checks (rasters bit for bit, tables exact, budgets' largest relative difference).

    python benchmarks/tiles_change_obia.py --results /work/run7/results/kamech_twin --out /tmp/tiles_bench

Nothing is written into ``--results``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def _job(code: str) -> dict:
    """Run ``code`` in a fresh Python process; wall s, CPU s and peak RSS (MB) of that process."""
    env = {**os.environ, "PYTHONPATH": str(REPO / "src")}
    t0 = time.perf_counter()
    p = subprocess.Popen([sys.executable, "-c", code], env=env, cwd=REPO)
    _, status, ru = os.wait4(p.pid, 0)
    wall = time.perf_counter() - t0
    if status != 0:
        raise RuntimeError(f"job failed ({status}):\n{code}")
    return {"wall_s": wall, "cpu_s": ru.ru_utime + ru.ru_stime, "peak_rss_mb": ru.ru_maxrss / 1024.0}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--results", type=Path, required=True, help="results/<site> of a finished default-twin run (read only)")
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--site", type=Path, default=REPO / "config" / "sites" / "kamech_twin.yaml")
    ap.add_argument("--tile-m", type=float, default=200.0)
    a = ap.parse_args(argv)
    import numpy as np
    import pandas as pd
    import rasterio

    from kitegully.change.params import THRESHOLD_METHODS
    from kitegully.config import load_yaml
    from kitegully.obia.stage import METHOD_KEYS

    cfg = load_yaml(a.site)
    r, out = a.results.resolve(), a.out.resolve()
    out.mkdir(parents=True, exist_ok=True)
    ext = cfg["twin"]["extent"]
    tiling = {"tile_m": a.tile_m, "width_m": float(ext["width_m"]), "height_m": float(ext["height_m"])}
    ch = cfg["change"]
    epochs = [{"name": f"epoch{n}", "dem": str(r / "dense" / sub / "dsm.tif"), "nodata": None,
               "correlation": str(r / "dense" / sub / "correlation.tif"),
               "accuracy": {"checkpoints": str(r / "inputs" / sub / "checkpoints.csv")}} for n, sub in ((1, ""), (2, "epoch2"))]
    masks = [{"name": "gully", "file": str(r / "gully" / "gully_polygons.gpkg"), "kind": "vector", "by": "gully_id", "unstable": True},
             {"name": "bare_soil", "file": str(r / "obia" / "kite" / "bare_soil.gpkg"), "kind": "vector", "by": None, "unstable": True}]
    heads, sections = str(r / "twin" / "observed" / "gully_heads.gpkg"), str(r / "polygons" / "cross_sections.gpkg")
    methods = {k: ch[k] for k in ("coregistration", "thresholds", "budget", "headcuts", "quality", "widening") if k in ch}
    obia = {k: cfg["obia"][k] for k in METHOD_KEYS}
    tile_cells = int(cfg["obia"]["kite_scale"]["tile_cells"])
    from kitegully.change.params import OUTPUTS
    from kitegully.terrain.tiling import TilingParams

    names = TilingParams(**tiling).names()
    ext_of = {"dod": "tif", "sigma_dod": "tif", "stable": "tif", "dod_map": "png", "budget_bars": "png", "histogram": "png",
              "variogram_png": "png"}

    def outs(d):
        d.mkdir(exist_ok=True)
        o = {k: str(d / f"{k}.{ext_of.get(k, 'csv')}") for k in OUTPUTS}
        o.update({f"thresholded_{m}": str(d / f"thresholded_{m}.tif") for m in THRESHOLD_METHODS})
        return o

    head = (f"import json\nfrom kitegully.change.params import ChangeParams\nfrom kitegully.terrain.tiling import TilingParams\n"
            f"E = json.loads({json.dumps(json.dumps(epochs))}); M = json.loads({json.dumps(json.dumps(masks))})\n"
            f"P = ChangeParams.from_config(json.loads({json.dumps(json.dumps(methods))}), seed={int(cfg['seed'])})\n"
            f"T = TilingParams(**{tiling!r}); CRS = {cfg['site']['crs']!r}\n")
    rows = []
    ref, til, w = outs(out / "change_untiled"), outs(out / "change_tiled"), out / "change_tiles"
    w.mkdir(exist_ok=True)
    rows.append({"product": "change", "job": "change_detect (untiled)", **_job(
        head + f"from kitegully.change.stage import detect_change\n"
               f"detect_change(E, M, {heads!r}, P, {ref!r}, site_crs=CRS, figure={ch['figure']!r}, sections_path={sections!r})\n")})
    rows.append({"product": "change", "job": "change_plan", **_job(
        head + f"from kitegully.change.tiles import plan_change\nplan_change(E, {str(w / 'plan.json')!r}, CRS)\n")})
    for n in names:
        rows.append({"product": "change", "job": f"change_stable_tile {n}", **_job(
            head + f"from kitegully.change.tiles import stable_tile\n"
                   f"stable_tile(E, M, {str(w / 'plan.json')!r}, P, T, {n!r}, {str(w / f'{n}.stable.npz')!r}, CRS)\n")})
    st = [str(w / f"{n}.stable.npz") for n in names]
    rows.append({"product": "change", "job": "change_coregister", **_job(
        head + f"from kitegully.change.tiles import coregister_tiles\n"
               f"coregister_tiles({st!r}, E, P, {str(w / 'coreg.json')!r}, CRS)\n")})
    for n in names:
        rows.append({"product": "change", "job": f"change_tile {n}", **_job(
            head + f"from kitegully.change.tiles import change_tile\n"
                   f"change_tile(E, M, {str(w / 'plan.json')!r}, {str(w / 'coreg.json')!r}, {str(w / f'{n}.stable.npz')!r}, P, T, "
                   f"{n!r}, {str(w / f'{n}.change.npz')!r}, CRS)\n")})
    ct = [str(w / f"{n}.change.npz") for n in names]
    rows.append({"product": "change", "job": "change_merge", **_job(
        head + f"from kitegully.change.tiles import merge_change\n"
               f"merge_change({ct!r}, {str(w / 'plan.json')!r}, {str(w / 'coreg.json')!r}, E, {heads!r}, P, {til!r}, site_crs=CRS, "
               f"figure={ch['figure']!r}, sections_path={sections!r})\n")})

    ortho, dsm = str(r / "dense" / "orthophoto.tif"), str(r / "dense" / "dsm.tif")
    ohead = (f"import json\nfrom kitegully.obia.scene import ObiaParams\nfrom kitegully.terrain.tiling import TilingParams\n"
             f"P = ObiaParams.from_config(json.loads({json.dumps(json.dumps(obia))})); T = TilingParams(**{tiling!r})\n")
    ko = out / "obia"
    ko.mkdir(exist_ok=True)
    rows.append({"product": "obia_kite", "job": "obia_kite_scale (untiled)", **_job(
        ohead + f"from kitegully.obia.kite import bare_soil_map\nimport json\n"
                f"thr = bare_soil_map({ortho!r}, {dsm!r}, {str(ko / 'untiled.tif')!r}, P, {tile_cells})\n"
                f"open({str(ko / 'untiled.json')!r}, 'w').write(json.dumps(thr.as_dict()))\n")})
    hists = [str(ko / f"{n}.hist.npz") for n in names]
    for n, h in zip(names, hists):
        rows.append({"product": "obia_kite", "job": f"obia_kite_histogram {n}", **_job(
            ohead + f"from kitegully.obia.kite_tiles import kite_histogram_tile\n"
                    f"kite_histogram_tile({ortho!r}, {dsm!r}, {h!r}, P, {tile_cells}, T, {n!r})\n")})
    maps = [str(ko / f"{n}.classes.npz") for n in names]
    for n, m in zip(names, maps):
        rows.append({"product": "obia_kite", "job": f"obia_kite_tile {n}", **_job(
            ohead + f"from kitegully.obia.kite_tiles import kite_map_tile\n"
                    f"kite_map_tile({ortho!r}, {dsm!r}, {hists!r}, {m!r}, P, {tile_cells}, T, {n!r})\n")})
    rows.append({"product": "obia_kite", "job": "obia_kite_merge (map only)", **_job(
        ohead + f"from kitegully.obia.kite_tiles import merge_kite_tiles\nimport json\n"
                f"thr = merge_kite_tiles({maps!r}, {hists!r}, {ortho!r}, {str(ko / 'tiled.tif')!r}, P)\n"
                f"open({str(ko / 'tiled.json')!r}, 'w').write(json.dumps(thr.as_dict()))\n")})

    checks = []
    for k in ("dod", "sigma_dod", "stable", *(f"thresholded_{m}" for m in THRESHOLD_METHODS)):
        with rasterio.open(ref[k]) as x, rasterio.open(til[k]) as y:
            u, v = x.read(1), y.read(1)
        n_diff = int((~((u == v) | (np.isnan(u) & np.isnan(v)) if u.dtype.kind == "f" else u == v)).sum())
        checks.append({"product": "change", "check": f"{k}.tif cells differing", "value": n_diff, "of": u.size})
    for k in ("coregistration", "sigma", "thresholds", "variogram", "headcuts", "widening"):
        checks.append({"product": "change", "check": f"{k}.csv identical", "value": int(pd.read_csv(ref[k]).equals(pd.read_csv(til[k]))), "of": 1})
    ba, bb = pd.read_csv(ref["budget"]), pd.read_csv(til["budget"])
    x, y = ba.iloc[:, 2:].to_numpy(float), bb.iloc[:, 2:].to_numpy(float)
    with np.errstate(invalid="ignore", divide="ignore"):
        rel = np.nanmax(np.where(np.abs(x) > 0, np.abs(x - y) / np.abs(x), np.abs(x - y)))
    checks.append({"product": "change", "check": "budget rows/order identical", "value": int(ba[["mask", "method"]].equals(bb[["mask", "method"]])), "of": len(ba)})
    checks.append({"product": "change", "check": "budget max relative difference", "value": float(rel), "of": x.size})
    with rasterio.open(ko / "untiled.tif") as x, rasterio.open(ko / "tiled.tif") as y:
        u, v = x.read(1), y.read(1)
    checks.append({"product": "obia_kite", "check": "bare_soil.tif cells differing", "value": int((u != v).sum()), "of": u.size})
    checks.append({"product": "obia_kite", "check": "threshold record identical",
                   "value": int(json.loads((ko / "untiled.json").read_text()) == json.loads((ko / "tiled.json").read_text())), "of": 1})
    jobs = pd.DataFrame(rows)
    jobs.to_csv(out / "tiles_benchmark.csv", index=False)
    pd.DataFrame(checks).to_csv(out / "tiles_checks.csv", index=False)
    print(jobs.to_string(index=False))
    print(pd.DataFrame(checks).to_string(index=False))
    for p, g in jobs.groupby("product", sort=False):
        un = g[g["job"].str.contains("untiled")]
        ti = g[~g["job"].str.contains("untiled")]
        print(f"{p}: untiled {un['wall_s'].sum():.1f} s wall / {un['cpu_s'].sum():.1f} s CPU / {un['peak_rss_mb'].max():.0f} MB; "
              f"tiled {len(ti)} jobs {ti['wall_s'].sum():.1f} s wall summed / {ti['cpu_s'].sum():.1f} s CPU / "
              f"largest job {ti['peak_rss_mb'].max():.0f} MB")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
