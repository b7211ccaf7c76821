"""Where the missed reference length lies, per ensemble twin (issue 15; evaluation only).

For every member of the twin ensemble (``benchmarks/twin_ensemble.py``: the default site and
``config/sites/ensemble/*.yaml``) this maps the gullies again on the member's existing
photogrammetric DSM (``<results>/<site>/dense/dsm.tif``, never rewritten) with the current
code and the member's merged ``gully:`` settings, and runs
:func:`gully_miss_analysis.analyse` on it: every metre of the scored reference (paper
protocol) not matched within the 5 m tolerance, by reason (no head on the gully, head placed
downstream, head snapped off the gully, path leaves the gully, traced but not in the map),
with the share of missed length near a filled depression/flat or near a DSM hole/edge, the
split by gully kind (wadi, gully, shallow) and a table of how far each used head sits from the
true centrelines, as digitised and as snapped.

Writes under ``--out`` (default ``results/ensemble_misses``): ``misses_by_member.csv/.md``
(% of each member's scored reference per reason, plus mean), ``misses_by_kind.csv`` (member ×
gully kind × reason, m), ``heads_<member>.csv``, ``missed_by_gully_<member>.csv``.

    PYTHONPATH=src .venv/bin/python benchmarks/gully_ensemble_misses.py \\
        --results /work/wt/ensrun/results [--members default,ens1] [--heads digitised] [--set head_snap=plane]
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import yaml

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "src"))
sys.path.insert(0, str(REPO / "benchmarks"))

from gully_miss_analysis import analyse  # noqa: E402
from twin_ensemble import BASE, ENSEMBLE_DIR, deep_merge, members  # noqa: E402

from kitegully.io.tables import write_table  # noqa: E402

log = logging.getLogger("gully_ensemble_misses")

REASONS = ["matched", "no head on this gully", "head downstream", "beside: head snapped off the gully",
           "beside: path leaves the gully", "traced, not mapped"]


def member_cfg(files: list[Path]) -> dict:
    """The member's merged config (base site file + its override)."""
    cfg = yaml.safe_load(BASE.read_text())
    for f in files:
        cfg = deep_merge(cfg, yaml.safe_load(f.read_text()))
    return cfg


def run(results: Path, names: list[str] | None, heads: str, sets: dict, out: Path, member_dir: Path = ENSEMBLE_DIR) -> pd.DataFrame:
    """Analyse every member; write the tables; return the per-member table (% of reference)."""
    out.mkdir(parents=True, exist_ok=True)
    rows, kinds = [], []
    for name, files in members(names, BASE, member_dir):
        cfg = member_cfg(files)
        cfg["gully"].update(sets)
        site = results / (cfg["site"]["name"] if name != "default" else cfg["site"]["name"])
        if not (site / "dense/dsm.tif").exists():
            log.warning("%s: no dense DSM under %s, skipped", name, site)
            continue
        tab, totals, scores, _res, df, heads_tab = analyse(cfg, site, heads, samples_out=True)
        ref = float(totals.sum())
        row = {"member": name, "reference_m": ref, "good_fit_5m_pct": scores["good_fit_5m_pct"],
               "false_positive_5m_pct": scores["false_positive_5m_pct"], "iou": scores.get("iou", np.nan)}
        for r in REASONS:
            row[f"{r} (%)"] = 100 * float(totals.get(r, 0.0)) / ref
        miss = df["reason"] != "matched"
        row["missed near a filled flat (%)"] = 100 * df.loc[miss & df["near_flat"], "length_m"].sum() / ref
        row["missed near a DSM hole/edge (%)"] = 100 * df.loc[miss & df["near_nodata"], "length_m"].sum() / ref
        # base rates: how much of the whole reference carries the flags (a flag found as often on matched
        # metres as on missed ones is no cause)
        row["reference near a filled flat (%)"] = 100 * df.loc[df["near_flat_any"], "length_m"].sum() / ref
        row["reference near a shrub/tree (%)"] = 100 * df.loc[df["near_object"], "length_m"].sum() / ref
        tnm = df["reason"] == "traced, not mapped"
        for w in ("head reach", "gap", "tail", "never mapped"):
            row[f"traced, not mapped: {w} (%)"] = 100 * df.loc[tnm & (df["traced_where"] == w), "length_m"].sum() / ref
        leaves = df["reason"] == "beside: path leaves the gully"
        for lab, m in (("matched", df["reason"] == "matched"), ("path leaves", leaves)):
            tot = df.loc[m, "length_m"].sum()
            row[f"{lab}: near a filled flat (% of it)"] = 100 * df.loc[m & df["near_flat_any"], "length_m"].sum() / tot if tot else np.nan
            row[f"{lab}: near a shrub/tree (% of it)"] = 100 * df.loc[m & df["near_object"], "length_m"].sum() / tot if tot else np.nan
        dig = heads_tab[heads_tab["source"] == "digitised"]
        row["digitised heads"] = len(dig)
        row["digitised heads on no gully (>reach)"] = int((dig["gully_id"] < 0).sum())
        row["snapped heads on their gully (<=2 m)"] = int(dig["snapped_on_gully"].sum())
        row["median digitised->centreline (m)"] = float(np.nanmedian(dig["digitised_to_centreline_m"])) if len(dig) else np.nan
        row["median snapped->centreline (m)"] = float(np.nanmedian(dig["snapped_to_centreline_m"])) if len(dig) else np.nan
        rows.append(row)
        k = df.groupby(["kind", "reason"])["length_m"].sum().rename("length_m").reset_index()
        k.insert(0, "member", name)
        kinds.append(k)
        write_table(heads_tab, out / f"heads_{name}.csv", floatfmt=".2f", markdown=False)
        write_table(tab, out / f"missed_by_gully_{name}.csv", floatfmt=".2f", markdown=False)
        log.info("%s: %s", name, {k_: (round(v, 1) if isinstance(v, float) else v) for k_, v in row.items()})
    res = pd.DataFrame(rows)
    if len(res):
        num = res.select_dtypes("number").mean()
        res = pd.concat([res, pd.DataFrame([{"member": "mean", **num.to_dict()}])], ignore_index=True)
    write_table(res, out / "misses_by_member.csv", floatfmt=".1f")
    if kinds:
        write_table(pd.concat(kinds, ignore_index=True), out / "misses_by_kind.csv", floatfmt=".0f", markdown=False)
    return res


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--results", required=True, help="results folder holding the members' site folders (read only)")
    ap.add_argument("--members", default=None)
    ap.add_argument("--member-dir", default=str(ENSEMBLE_DIR.relative_to(REPO)), help="folder of member override files (config/sites/holdout)")
    ap.add_argument("--heads", default="digitised", choices=["digitised", "automatic", "both"])
    ap.add_argument("--set", action="append", default=[], help="gully key=value (yaml value) overrides")
    ap.add_argument("--out", default="results/ensemble_misses")
    a = ap.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    sets = {}
    for kv in a.set:
        k, v = kv.split("=", 1)
        sets[k] = yaml.safe_load(v)
    res = run(Path(a.results), a.members.split(",") if a.members else None, a.heads, sets, REPO / a.out, REPO / a.member_dir)
    with pd.option_context("display.width", 250, "display.max_columns", 40):
        print(res.round(1).T.to_string())


if __name__ == "__main__":
    main()
