#!/usr/bin/env python
"""The polygons stage's [I] rules, each switched off alone, on every ensemble member's DSM (issue 16).

For each rule (``upper_edges_only``, ``edge_ground_m`` (= ``breaklines.ground_segment_m``:
upper edges tested on the DEM instead of the ground), ``bridge``, ``terrain_held``, ``below_rims``,
``ground_segment_m``) the member's site settings are used with only that rule set to its
"off" value, and the member is scored as ``benchmarks/polygons_ensemble.py`` does (without the
Table 1 comparison, to save time). Reported: mean and worst over the members of the wide-gully
IoU, the median absolute width and depth errors and the volume error (mean of |x|, worst with
its sign). A check of whether each rule earns its place on members it was not written on —
not a way to choose settings: every member here carries the truth the stage is reported against.

Usage::

    .venv/bin/python benchmarks/polygons_rules_off.py --root results [--members default,ens1,...]

Writes ``results/benchmarks/polygons_rules_off.csv`` (per member and rule) and ``.md`` (summary).
Cost: rules × members stage runs (~25 s each on the shared machine).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import numpy as np
import pandas as pd

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "src"))
sys.path.insert(0, str(REPO / "benchmarks"))

import polygons_ensemble as pe  # noqa: E402

from kitegully.polygons import PolygonParams  # noqa: E402

RULES_OFF = {"upper_edges_only": False, "edge_ground_m": 0.0, "bridge": "all", "terrain_held": False, "below_rims": False, "ground_segment_m": 0.0}
_NO_TABLE1 = pd.DataFrame({"statistic": [f"{k} (-)" for k in ("auto_in_union_pct", "intersection_covered_pct", "union_covered_pct",
                                                              "auto_over_intersection", "mean_auto_over_mean_manual_pct")],
                           "value": [np.nan] * 5})


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--root", default=str(REPO / "results"))
    ap.add_argument("--members", default="default," + ",".join(p.stem for p in sorted(pe.ENSEMBLE_DIR.glob("*.yaml"))))
    ap.add_argument("--out", default=str(REPO / "results" / "benchmarks" / "polygons_rules_off"))
    args = ap.parse_args()
    pe.regenerate_table1 = lambda *a, **k: (None, _NO_TABLE1, None)
    site_from_config = PolygonParams.from_config.__func__
    rows = []
    try:
        for rule, value in {"none": None, **RULES_OFF}.items():
            def from_config(cls, cfg, rule=rule, value=value):
                p = site_from_config(cls, cfg)
                return p if rule == "none" else dataclasses.replace(p, **{rule: value})

            PolygonParams.from_config = classmethod(from_config)
            for m in args.members.split(","):
                r = pe.score_member(m, Path(args.root))
                r["off"] = rule if rule == "none" else f"{rule}={value}"
                rows.append(r)
                print(r["off"], m, r.get("status"), {k: round(r[k], 3) for k in ("iou_wide", "width_med_abs_m", "depth_med_abs_m", "volume_error_pct") if k in r},
                      flush=True)
    finally:
        PolygonParams.from_config = classmethod(site_from_config)
    df = pd.DataFrame(rows)
    ok = df[df["status"] == "ok"]
    g = ok.groupby("off", sort=False).agg(
        members=("member", "size"), iou_mean=("iou_wide", "mean"), iou_worst=("iou_wide", "min"), width_mean=("width_med_abs_m", "mean"),
        width_worst=("width_med_abs_m", "max"), depth_mean=("depth_med_abs_m", "mean"), depth_worst=("depth_med_abs_m", "max"),
        volume_abs_mean_pct=("volume_error_pct", lambda v: v.abs().mean()), volume_worst_pct=("volume_error_pct", lambda v: v[v.abs().idxmax()]))
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    df.to_csv(out.with_suffix(".csv"), index=False)
    text = "# Polygons stage: each [I] rule off alone, all members\n\n" + g.to_markdown(floatfmt=".3g") + "\n"
    out.with_suffix(".md").write_text(text, encoding="utf-8")
    print(text)


if __name__ == "__main__":
    main()
