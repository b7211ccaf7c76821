#!/usr/bin/env python
"""The polygons stage on every ensemble member's photogrammetric DSM (issue 16 targets, issue 15 ensemble).

For each member of the twin ensemble (``default`` = config/sites/kamech_twin.yaml, ``ensN`` =
config/sites/ensemble/ensN.yaml merged on top of it) whose dense DSM exists under
``<root>/<site>/dense/dsm.tif`` (written by ``benchmarks/twin_ensemble.py``), the script runs
the stage's library entry points (:func:`kitegully.polygons.measure_polygons` with
:meth:`PolygonParams.from_config` of the member's merged ``polygons`` section) and scores the
t = 0.5 m polygons and their cross-sections against the member's truth
(:func:`kitegully.polygons.evaluate_against_truth`), as the ``polygons_evaluate`` rule does.

Reported per member, then mean and worst, against the issue-16 targets: IoU of the gullies
wider than 2 m (their cells) ≥ 0.6, median absolute width error ≤ 1 m, median absolute depth
error ≤ 0.15 m, total volume within 15 %. Also the paper's Table 1 comparison of the t = 0.5 m polygon
A with the union U and intersection I of the nine simulated operators (as the ``polygons_table1``
rule: |A∩U|/|A|, |A∩I|/|I|, |A∩U|/|U|, |A|/|I|, mean auto / mean manual; paper 99.8 %, 99.5 %,
79.7 %, 1.7, 92.5 %).

Usage::

    .venv/bin/python benchmarks/polygons_ensemble.py [--root results] [--members default,ens1,...]
    .venv/bin/python benchmarks/polygons_ensemble.py --members h1,h2 --out results/benchmarks/polygons_holdout  # held-out twins
    .venv/bin/python benchmarks/polygons_ensemble.py --dem twin/truth/dtm.tif --water-empty  # the method on the true ground (a check only)
    .venv/bin/python benchmarks/polygons_ensemble.py --set polygons.morphometry.threshold_m=0.25 \
        --set "polygons.conditioning.thresholds_m=[0.25, 0.5, 1.0]"   # another setting on every member (yaml values)

Writes ``results/benchmarks/polygons_ensemble.csv`` and ``.md`` (with ``--sections`` also
``polygons_ensemble_sections.csv``, every matched section's errors). A member whose DSM or truth
is missing is listed as skipped.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import yaml

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "src"))

from kitegully.config import load_yaml  # noqa: E402
from kitegully.io.raster import Raster  # noqa: E402
from kitegully.io.vectors import read_vector  # noqa: E402
from kitegully.polygons import PolygonParams, evaluate_against_truth, measure_polygons  # noqa: E402
from kitegully.polygons.evaluation import observable_region_from_files, regenerate_table1  # noqa: E402

BASE = REPO / "config" / "sites" / "kamech_twin.yaml"
ENSEMBLE_DIR = REPO / "config" / "sites" / "ensemble"
HOLDOUT_DIR = REPO / "config" / "sites" / "holdout"  # held-out twins (--members h1,h2), never used to write or choose a method
TARGETS = {"iou_wide": (">=", 0.6), "width_med_abs_m": ("<=", 1.0), "depth_med_abs_m": ("<=", 0.15), "volume_error_pct": ("abs<=", 15.0)}


def _merge(base: dict, over: dict) -> dict:
    out = dict(base)
    for k, v in over.items():
        out[k] = _merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


def _dotted(key: str, value) -> dict:
    """``a.b.c`` and a value as the nested mapping ``{a: {b: {c: value}}}``."""
    for part in reversed(key.split(".")):
        value = {part: value}
    return value


def member_config(member: str, overrides: dict | None = None) -> dict:
    """The member's merged site configuration (base site file + its override file + ``overrides``)."""
    cfg = load_yaml(BASE)
    if member != "default":
        own = ENSEMBLE_DIR / f"{member}.yaml"
        cfg = _merge(cfg, load_yaml(own if own.exists() else HOLDOUT_DIR / f"{member}.yaml"))
    return _merge(cfg, overrides or {})


def water_left_empty(dem: Raster, truth: Path) -> Raster:
    """The DEM with the twin's open water (land-cover class ``water``) set to NaN (evaluation only).

    A photogrammetric DSM finds no match on calm water and the stage leaves such regions
    empty; a twin's true DSM and DTM hold the water surface or the reservoir's bed there. With
    the water left empty the stage applies the same open-water rule to all three surfaces.
    """
    lc = Raster.read(truth / "landcover.tif")
    classes = pd.read_csv(truth / "landcover_classes.csv")
    if lc.data.shape != dem.data.shape:
        raise SystemExit(f"{truth / 'landcover.tif'}: grid {lc.data.shape} differs from the DEM's {dem.data.shape}")
    water = classes.loc[classes["name"] == "water", "code"].to_numpy()
    data = np.array(dem.data, dtype=np.float32)
    data[np.isin(lc.data, water)] = np.nan
    return Raster(data, dem.grid, np.nan)


def evaluate_member(cfg: dict, truth: Path, polygons, sections, grid, region) -> dict:
    """:func:`kitegully.polygons.evaluate_against_truth` with the member's truth files and evaluation settings (as the ``polygons_evaluate`` rule)."""
    return evaluate_against_truth(polygons, sections, read_vector(truth / "gully_polygons.gpkg"), read_vector(truth / "gully_centrelines.gpkg"), grid,
                                  {k: v for k, v in cfg["polygons"]["evaluation"].items() if k != "operators"},
                                  cfg["twin"]["gullies"]["u_shape_exponent"], region=region)


def score_member(member: str, root: Path, dem_rel: str = "dense/dsm.tif", water_empty: bool = False,
                 overrides: dict | None = None, sections: list | None = None) -> dict:
    """Run the stage on one member's DSM (or another DEM under its site folder) and score it; ``status`` says why a member was skipped.

    ``water_empty``: the twin's open water set to NaN first (:func:`water_left_empty`; for its true surfaces).
    ``overrides``: nested config values merged over the member's (``--set``).
    ``sections``: when a list, the member's matched sections with their errors (``morphometry_errors``'
    per-section table and a ``member`` column) are appended to it (``--sections``).
    """
    cfg = member_config(member, overrides)
    site = root / cfg["site"]["name"]
    dsm, truth = site / dem_rel, site / "twin" / "truth"
    row: dict = {"member": member, "site": cfg["site"]["name"]}
    missing = [str(p) for p in (dsm, truth / "gully_polygons.gpkg", truth / "gully_centrelines.gpkg") if not p.exists()]
    if missing:
        return {**row, "status": f"skipped: no {missing[0]}"}
    poly = cfg["polygons"]
    r = Raster.read(dsm)
    if water_empty:
        r = water_left_empty(r, truth)
    t0 = time.perf_counter()
    res = measure_polygons(r.data, r.grid, PolygonParams.from_config(poly), dem_name=str(dsm))
    run_s = time.perf_counter() - t0
    # the truth a survey can see: the grid's extent less the reservoir (as the polygons_evaluate rule)
    region = observable_region_from_files(res.grid, truth / "landcover.tif", truth / "landcover_classes.csv")
    ev = evaluate_member(cfg, truth, res.polygons[poly["morphometry"]["threshold_m"]], res.sections, res.grid, region)
    if sections is not None:
        sections.append(ev["sections"].assign(member=member))
    sc = ev["scores"].set_index("kind")
    e = ev["errors"].set_index("quantity")
    thr = poly["morphometry"]["threshold_m"]
    _, comp, _ = regenerate_table1(res.polygons, read_vector(truth / "gully_polygons.gpkg"), read_vector(truth / "gully_centrelines.gpkg"), res.grid,
                                   poly["evaluation"]["operators"], cfg["seed"], cfg["twin"]["gullies"]["u_shape_exponent"], thr, region=region)
    t1 = dict(zip(comp["statistic"].str.split(" ").str[0], comp["value"]))
    row.update({"A_in_U_pct": t1["auto_in_union_pct"], "I_covered_pct": t1["intersection_covered_pct"], "U_covered_pct": t1["union_covered_pct"],
                "A_over_I": t1["auto_over_intersection"], "auto_over_manual_pct": t1["mean_auto_over_mean_manual_pct"]})
    return {**row, "status": "ok", "iou_wide": sc.loc["wide", "iou"], "iou_all": sc.loc["all", "iou"], "recall_all": sc.loc["all", "recall"],
            "precision_all": sc.loc["all", "precision"], "sections": int(len(res.sections)),
            "width_med_abs_m": e.loc["width (m)", "median_abs_error"], "depth_med_abs_m": e.loc["depth (m)", "median_abs_error"],
            "depth_med_m": e.loc["depth (m)", "median_error"], "area_med_abs_m2": e.loc["area (m2)", "median_abs_error"],
            "volume_error_pct": e.loc["volume, all sections vs all true gullies (m3)", "error_pct"],
            "volume_matched_error_pct": e.loc["volume, gullies with matched sections (m3)", "error_pct"],
            "volume_error_incl_unobservable_pct": e.loc["volume, all sections vs all true gullies incl. not observable (m3)", "error_pct"],
            "unobservable_volume_pct": 100 * e.loc["true volume not observable (under open water, beyond the DEM) (m3)", "true"]
            / e.loc["volume, all sections vs all true gullies incl. not observable (m3)", "true"], "run_s": run_s}


def summarise(df: pd.DataFrame) -> pd.DataFrame:
    """Mean and worst of the scored members, and whether each target is met by the mean and the worst.

    For the volume (target |x| ≤ 15 %) the mean is that of the errors' sizes |x|, the worst the
    largest |x| with its sign.
    """
    ok = df[df["status"] == "ok"]
    rows = []
    for col, (op, lim) in TARGETS.items():
        v = ok[col].to_numpy(float)
        if op == ">=":
            worst, met = v.min(), lambda x: x >= lim
        elif op == "<=":
            worst, met = v.max(), lambda x: x <= lim
        else:
            worst, met = v[np.argmax(np.abs(v))], lambda x: abs(x) <= lim
        mean = np.abs(v).mean() if op == "abs<=" else v.mean()  # volume: the mean size of the errors
        rows.append({"quantity": col, "target": f"{op.replace('abs', '|x| ')} {lim:g}", "members": len(v), "mean": mean, "worst": worst,
                     "mean meets": bool(met(mean)), "worst meets": bool(met(worst))})
    return pd.DataFrame(rows)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--root", default=str(REPO / "results"), help="results folder holding <site>/dense/dsm.tif and <site>/twin/truth/")
    ap.add_argument("--members", default="default," + ",".join(p.stem for p in sorted(ENSEMBLE_DIR.glob("*.yaml"))))
    ap.add_argument("--dem", default="dense/dsm.tif", help="DEM under <root>/<site>/ the stage runs on (twin/truth/dtm.tif: the true ground, a check only)")
    ap.add_argument("--water-empty", action="store_true",
                    help="set the twin's open water to NaN first, as a photogrammetric DSM leaves it (for --dem twin/truth/dsm.tif or dtm.tif)")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="dotted config key and yaml value merged over every member's configuration (a trial, not the site's setting)")
    ap.add_argument("--out", default=str(REPO / "results" / "benchmarks" / "polygons_ensemble"))
    ap.add_argument("--sections", action="store_true",
                    help="also write every member's matched sections with their errors to <out>_sections.csv (benchmarks/polygons_depth_bounds.py reads it)")
    args = ap.parse_args()
    overrides: dict = {}
    for item in args.set:
        key, _, value = item.partition("=")
        overrides = _merge(overrides, _dotted(key.strip(), yaml.safe_load(value)))
    rows: list[dict] = []
    sections: list | None = [] if args.sections else None
    for m in args.members.split(","):
        rows.append(score_member(m, Path(args.root), args.dem, args.water_empty, overrides, sections))
        print({k: (round(v, 3) if isinstance(v, float) else v) for k, v in rows[-1].items()}, flush=True)
    df = pd.DataFrame(rows)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    df.to_csv(out.with_suffix(".csv"), index=False)
    if sections:
        pd.concat(sections, ignore_index=True).to_csv(out.with_name(out.name + "_sections.csv"), index=False)
    text = "# Polygons stage on the ensemble members' photogrammetric DSMs\n\n" + df.to_markdown(index=False, floatfmt=".3g") + "\n"
    if (df["status"] == "ok").any():
        text += "\n## Mean and worst against the issue-16 targets\n\n" + summarise(df).to_markdown(index=False, floatfmt=".3g") + "\n"
    out.with_suffix(".md").write_text(text, encoding="utf-8")
    print(text)


if __name__ == "__main__":
    main()
