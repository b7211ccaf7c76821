"""Gully stage alone over the twin ensemble, on the truth-plus-noise stand-in (NOT the photogrammetric DSM).

A cheap stand-in for ``make ensemble`` when the whole chain cannot be run: per member
(``default`` = config/sites/kamech_twin.yaml, plus config/sites/ensemble/*.yaml merged on
top) the twin's truth and survey are generated without texture (epoch 1, with the honest
digitised heads of twin/survey.py), the gully stage maps the stand-in DEM (truth DTM +
``gully.standin`` noise) with digitised and with automatic heads, and both are scored with
the paper's protocol. What the stand-in lacks: photogrammetric errors (vegetation in the
DSM, matching gaps, the open-water hole of the reservoir), so it is an upper bound on the
digitised-head scores and not a substitute for the ensemble.

    PYTHONPATH=src .venv/bin/python benchmarks/gully_ensemble_standin.py [--members default,ens1] [--out DIR]
"""

from __future__ import annotations

import argparse
import logging
import sys
import time
from pathlib import Path

import pandas as pd
import yaml

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "src"))
sys.path.insert(0, str(REPO / "benchmarks"))

from gully_heads_eval import run as run_gully  # noqa: E402
from twin_ensemble import BASE, deep_merge, members, summarise  # noqa: E402

from kitegully.twin import TwinParams  # noqa: E402
from kitegully.twin.site import build_site, generate_epoch  # noqa: E402

log = logging.getLogger("gully_ensemble_standin")

COLS = ["member", "heads", "n_heads", "good_fit_2m_pct", "false_positive_2m_pct", "good_fit_5m_pct", "false_positive_5m_pct",
        "false_negative_5m_pct", "good_fit_15m_pct", "false_positive_15m_pct", "iou", "area_precision", "area_recall",
        "head_precision", "head_recall", "head_median_distance_m"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--members", default=None)
    ap.add_argument("--out", default="results/ensemble_standin")
    ap.add_argument("--set", action="append", default=[], help="gully key=value overrides (YAML value)")
    ap.add_argument("--mask-water", action="store_true", help="stand-in empty over open water, like the DSM")
    ap.add_argument("--modes", default="digitised,automatic", help="head sources (digitised, automatic, both)")
    a = ap.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    out = REPO / a.out
    rows = []
    for name, files in members(a.members.split(",") if a.members else None, BASE):
        cfg = yaml.safe_load(BASE.read_text())
        for f in files:
            cfg = deep_merge(cfg, yaml.safe_load(f.read_text()))
        cfg["gully"]["crowns"] = {"enabled": False}  # the stand-in DEM has no orthophoto (gully.crowns needs one)
        for kv in a.set:
            k, v = kv.split("=", 1)
            cfg["gully"][k] = yaml.safe_load(v)
        twin = out / name / "twin"
        if not (twin / "observed/gully_heads.gpkg").exists():
            t0 = time.perf_counter()
            site = build_site(TwinParams.from_config(cfg["twin"]), cfg["site"]["crs"], cfg["seed"], epoch=1)
            generate_epoch(site, twin, texture=False)
            log.info("%s: twin generated in %.0f s", name, time.perf_counter() - t0)
        for r in run_gully(cfg, str(twin), None, modes=a.modes.split(","), mask_water=a.mask_water):
            rows.append({"member": name, **r})
    df = pd.DataFrame(rows)
    out.mkdir(parents=True, exist_ok=True)
    parts = []
    for mode, sub in df.groupby("heads", sort=False):
        s = summarise(sub.drop(columns=["heads"]).reset_index(drop=True))
        s.insert(1, "heads", mode)
        parts.append(s)
    full = pd.concat(parts, ignore_index=True)
    full.to_csv(out / "summary.csv", index=False)
    cols = [c for c in COLS if c in full.columns]
    md = ["# Gully stage over the twin ensemble on the truth-plus-noise stand-in (NOT the photogrammetric DSM)\n",
          "| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for _, r in full.iterrows():
        md.append("| " + " | ".join(f"{r[c]:.3g}" if isinstance(r[c], float) else str(r[c]) for c in cols) + " |")
    (out / "summary.md").write_text("\n".join(md) + "\n")
    print("\n".join(md))


if __name__ == "__main__":
    main()
