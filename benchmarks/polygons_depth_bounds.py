#!/usr/bin/env python
"""Where the polygons' depth error lies, and how far any correction of its biases could take it (evaluation only).

Reads the per-section errors that ``benchmarks/polygons_ensemble.py --sections`` writes (one or
more ``*_sections.csv``: every matched t = 0.5 m cross-section of every twin, its true shape and
width, measured and true maximum depth) and reports:

1. **By kind** (per twin and pooled): narrow U, narrow V (true width ≤ ``--wide-m``) and wide
   sections, with count, median error and median absolute error. [I] 6 m: session 9 found the
   pre-incision surface's bend between the rims ≤ 0.02 m for narrower sections (the twin cuts its
   wide gullies into a V-shaped valley floor of cross slope 0.04, which only the wide ones span).
2. **Bounds** on the issue-16 depth target (median absolute error ≤ 0.15 m per twin): the
   per-twin median absolute error after removing, exactly, the median error of chosen kinds:
   pooled over all twins (what one correction per kind, perfectly known, could do) and each
   twin's own (an oracle no method has). Neither is a method; both read the truth. They say
   how much of the error is bias that a correction could remove, and how much is scatter
   between sections that no per-kind correction touches.

Usage::

    .venv/bin/python benchmarks/polygons_ensemble.py --sections --out results/benchmarks/polygons_six
    .venv/bin/python benchmarks/polygons_ensemble.py --sections --members h1,...,h18 --out results/benchmarks/polygons_h
    .venv/bin/python benchmarks/polygons_depth_bounds.py results/benchmarks/polygons_six_sections.csv \\
        results/benchmarks/polygons_h_sections.csv --out results/benchmarks/polygons_depth_bounds

Writes ``<out>_by_kind.csv``, ``<out>.csv`` (the bounds) and ``<out>.md``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd

TARGET_M = 0.15  # issue 16: median absolute depth error per twin


def section_kinds(sections: pd.DataFrame, wide_m: float) -> pd.Series:
    """``wide`` where the true width exceeds ``wide_m``, else the true shape (``U`` or ``V``)."""
    return pd.Series(np.where(sections["width_true_m"] > wide_m, "wide", sections["shape"]), index=sections.index)


def by_kind(sections: pd.DataFrame) -> pd.DataFrame:
    """Count, median error and median absolute error of the depth per twin and kind, and pooled per kind."""
    def table(g) -> pd.DataFrame:
        e = g["depth_error_m"]
        return pd.DataFrame({"sections": e.size(), "median_error_m": e.median(), "median_abs_error_m": e.apply(lambda x: x.abs().median())})
    per = table(sections.groupby(["member", "kind"])).reset_index()
    pooled = table(sections.groupby("kind")).reset_index().assign(member=f"all {sections['member'].nunique()} twins")
    return pd.concat([per, pooled], ignore_index=True)[["member", "kind", "sections", "median_error_m", "median_abs_error_m"]]


def bias_bounds(sections: pd.DataFrame) -> pd.DataFrame:
    """Per-twin median |depth error| with chosen kinds' median errors removed exactly, summarised over the twins.

    Returns
    -------
    DataFrame
        One row per variant: which kinds, pooled or per-twin medians, and over the twins the mean
        and worst median absolute error, the worst twin and how many twins meet ``TARGET_M``.
    """
    e0 = sections["depth_error_m"]
    variants = [("none (as measured)", [], "pooled")]
    for kinds in (["V"], ["wide"], ["V", "wide"], ["U", "V", "wide"]):
        variants.append((" + ".join(kinds), kinds, "pooled"))
    variants.append(("U + V + wide", ["U", "V", "wide"], "each twin's own"))
    rows = []
    for name, kinds, how in variants:
        e = e0.copy()
        for k in kinds:
            sel = sections["kind"] == k
            if how == "pooled":
                e[sel] = e0[sel] - e0[sel].median()
            else:
                e[sel] = e0[sel] - e0[sel].groupby(sections.loc[sel, "member"]).transform("median")
        per = e.abs().groupby(sections["member"]).median()
        rows.append({"bias removed": name, "medians": how, "twins": per.size, "mean_m": per.mean(), "worst_m": per.max(),
                     "worst_twin": per.idxmax(), f"twins_at_or_below_{TARGET_M:g}_m": int((per <= TARGET_M).sum())})
    return pd.DataFrame(rows)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("sections", nargs="+", help="*_sections.csv written by polygons_ensemble.py --sections")
    ap.add_argument("--wide-m", type=float, default=6.0, help="true width above which a section counts as wide (m)")
    ap.add_argument("--out", default="results/benchmarks/polygons_depth_bounds")
    args = ap.parse_args()
    d = pd.concat([pd.read_csv(p) for p in args.sections], ignore_index=True).dropna(subset=["depth_error_m"])
    d["kind"] = section_kinds(d, args.wide_m)
    kinds, bounds = by_kind(d), bias_bounds(d)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    kinds.to_csv(out.with_name(out.name + "_by_kind.csv"), index=False)
    bounds.to_csv(out.with_suffix(".csv"), index=False)
    pooled = kinds[kinds["member"].str.startswith("all ")]
    text = ("# Polygons: the depth error by section kind, and bounds of a bias correction (evaluation only)\n\n"
            f"Sections: {len(d)} matched, {d['member'].nunique()} twins; wide = true width > {args.wide_m:g} m.\n\n"
            "## By kind, pooled\n\n" + pooled.to_markdown(index=False, floatfmt=".3f") +
            "\n\n## Median |depth error| per twin with biases removed exactly (reads the truth; not a method)\n\n"
            + bounds.to_markdown(index=False, floatfmt=".3f") + "\n")
    out.with_suffix(".md").write_text(text, encoding="utf-8")
    print(text)


if __name__ == "__main__":
    main()
