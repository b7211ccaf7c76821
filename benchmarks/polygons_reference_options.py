#!/usr/bin/env python
"""Depth reference options of the polygons stage on every ensemble member (issue 16).

The stage runs once per member on its photogrammetric DSM (or its pickled result from
``polygons_depth_diagnosis.py`` is reused); its t = 0.5 m polygons and rims are then measured
again with each depth reference option (``line``, the site setting before session 9; ``banks`` / ``bank_lines``
with the bank fit length of the option, and where a section end without a rim stays, ``no_rim``), on the DSM and, as a check of the method alone, on the
twin's true ground brought to the stage grid by the stage's minimum-z resampling. Scored as the
``polygons_evaluate`` rule does (median |error| and bias of width and depth, total volume),
and the total volume error split into the true volume the matched sections stand for (coverage),
the matched sections' area error and the volume of sections with no true reach within the match
distance (false polygons): total = coverage × (1 + area error) + unmatched − 1.

Evaluation only; the options and their values are stated from the geometry in README and the site
file, not chosen here.

Usage::

    .venv/bin/python benchmarks/polygons_reference_options.py [--members default,ens1] [--options line,banks:4.5]

Writes ``results/benchmarks/polygons_reference_options.csv`` and ``.md``.
"""

from __future__ import annotations

import argparse
import pickle
import sys
from pathlib import Path

import numpy as np
import pandas as pd

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "src"))
sys.path.insert(0, str(REPO / "benchmarks"))

from polygons_ensemble import ENSEMBLE_DIR, member_config  # noqa: E402

from kitegully.io.raster import Raster  # noqa: E402
from kitegully.io.vectors import read_vector  # noqa: E402
from kitegully.polygons.evaluation import observable_region_from_files  # noqa: E402
from kitegully.polygons import PolygonParams, evaluate_against_truth, measure_polygons  # noqa: E402
from kitegully.polygons.dem_prep import min_z_resample  # noqa: E402
from kitegully.polygons.morphometry import measure_sections  # noqa: E402


def stage_result(member: str, root: Path, cache: Path | None):
    cfg = member_config(member)
    p = PolygonParams.from_config(cfg["polygons"])
    f = cache / f"{member}.pkl" if cache else None
    if f is not None and f.exists():
        return cfg, p, pickle.loads(f.read_bytes())
    r = Raster.read(root / cfg["site"]["name"] / "dense" / "dsm.tif")
    res = measure_polygons(r.data, r.grid, p, dem_name=member)
    if f is not None:
        f.parent.mkdir(parents=True, exist_ok=True)
        f.write_bytes(pickle.dumps(res))
    return cfg, p, res


def score(member: str, root: Path, options: list[str], cache: Path | None) -> list[dict]:
    cfg, p, res = stage_result(member, root, cache)
    truth = root / cfg["site"]["name"] / "twin" / "truth"
    poly = cfg["polygons"]
    thr = p.morph_threshold_m
    t_poly, t_cl = read_vector(truth / "gully_polygons.gpkg"), read_vector(truth / "gully_centrelines.gpkg")
    evcfg = {k: v for k, v in poly["evaluation"].items() if k != "operators"}
    u_exp = cfg["twin"]["gullies"]["u_shape_exponent"]
    rr = Raster.read(truth / "dtm.tif")
    zt, _ = min_z_resample(rr.data, rr.grid, p.cell_m)
    h, w = res.dem.shape
    zt = np.asarray(zt)[:h, :w]
    surfaces = {"dsm": res.dem, "true_dtm": np.where(np.isfinite(zt), zt, res.dem)}
    # the truth a survey can see (outside the reservoir), as the polygons_evaluate rule
    region = observable_region_from_files(res.grid, truth / "landcover.tif", truth / "landcover_classes.csv")
    rows = []
    for opt in options:
        ref, fit, no_rim = (opt.split(":") + ["", ""])[:3]
        for sname, z in surfaces.items():
            _, sec, _ = measure_sections(res.labels[thr], res.polygons[thr], z, res.level, res.grid, p.section_spacing_m, ref, p.smooth_step_m,
                                         p.snakes_alpha, p.snakes_beta, p.branches, res.rims, p.rim_search_m, p.prolong_axes, p.ground_segment_m,
                                         bank_fit_m=float(fit or 0.0), no_rim=no_rim or "outline")
            ev = evaluate_against_truth(res.polygons[thr], sec, t_poly, t_cl, res.grid, evcfg, u_exp, region=region)
            e = ev["errors"].set_index("quantity")
            per = ev["sections"]
            sc = ev["scores"].set_index("kind")
            row = {"member": member, "reference": opt, "surface": sname, "sections": len(sec), "matched": len(per),
                   "iou_wide": sc.loc["wide", "iou"], "width_med_abs_m": e.loc["width (m)", "median_abs_error"],
                   "depth_med_abs_m": e.loc["depth (m)", "median_abs_error"], "depth_bias_m": e.loc["depth (m)", "median_error"],
                   "depth_p90_m": e.loc["depth (m)", "p90_abs_error"],
                   "depth_bias_U_m": float(per.loc[per["shape"] == "U", "depth_error_m"].median()),
                   "depth_bias_V_m": float(per.loc[per["shape"] == "V", "depth_error_m"].median()),
                   "area_med_err_m2": e.loc["area (m2)", "median_error"],
                   "volume_error_pct": e.loc["volume, all sections vs all true gullies (m3)", "error_pct"],
                   "matched_volume_error_pct": e.loc["volume, gullies with matched sections (m3)", "error_pct"]}
            v_true = e.loc["volume, all sections vs all true gullies (m3)", "true"]
            v_all = float((sec["area_m2"] * sec["slab_m"]).sum())
            v_m = float((per["area_m2"] * per["slab_m"]).sum())
            v_mt = float((per["area_true_m2"] * per["slab_m"]).sum())
            row.update({"true_volume_covered_pct": 100 * v_mt / v_true,  # true volume of the reaches the matched sections stand for
                        "matched_area_error_pct": 100 * (v_m - v_mt) / v_mt if v_mt else np.nan,  # their sections' areas against the truth
                        "unmatched_volume_pct": 100 * (v_all - v_m) / v_true})  # sections with no true reach within the match distance
            rows.append(row)
            print({k: (round(v, 3) if isinstance(v, float) else v) for k, v in row.items()}, flush=True)
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--root", default="/work/wt/ensrun/results", help="results folder of the ensemble members")
    ap.add_argument("--default-root", default="/work/run10/results", help="results folder of the default twin")
    ap.add_argument("--members", default="default," + ",".join(q.stem for q in sorted(ENSEMBLE_DIR.glob("*.yaml"))))
    ap.add_argument("--options", default="line,banks:4.5", help="comma-separated reference[:bank_fit_m[:no_rim]]")
    ap.add_argument("--cache", default=str(REPO / "results" / "benchmarks" / "polygons_depth_cache"))
    ap.add_argument("--out", default=str(REPO / "results" / "benchmarks" / "polygons_reference_options"))
    args = ap.parse_args()
    cache = Path(args.cache) if args.cache else None
    rows = []
    for m in args.members.split(","):
        rows += score(m, Path(args.default_root if m == "default" else args.root), args.options.split(","), cache)
    df = pd.DataFrame(rows)
    agg = df.groupby(["reference", "surface"]).agg(
        iou_wide_mean=("iou_wide", "mean"), iou_wide_worst=("iou_wide", "min"), width_mean=("width_med_abs_m", "mean"),
        width_worst=("width_med_abs_m", "max"), depth_mean=("depth_med_abs_m", "mean"), depth_worst=("depth_med_abs_m", "max"),
        volume_mean_abs=("volume_error_pct", lambda v: float(np.abs(v).mean())),
        volume_worst=("volume_error_pct", lambda v: float(v.to_numpy()[np.argmax(np.abs(v.to_numpy()))]))).reset_index()
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    df.to_csv(out.with_suffix(".csv"), index=False)
    text = ("# Polygons: depth reference options on the ensemble\n\n" + df.to_markdown(index=False, floatfmt=".3f")
            + "\n\n## Mean / worst over the members\n\n" + agg.to_markdown(index=False, floatfmt=".3f") + "\n")
    out.with_suffix(".md").write_text(text, encoding="utf-8")
    print(text)


if __name__ == "__main__":
    main()
