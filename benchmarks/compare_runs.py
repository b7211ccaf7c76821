"""Compare the tables (and optionally rasters) of two results folders of the same site.

Used to show that a refactor changes no number: every CSV under ``before`` must equal its
counterpart under ``after`` exactly, apart from rows or columns that measure the run
itself (wall time, CPU time, memory, speed), which are listed and skipped.

    python benchmarks/compare_runs.py results_before/kamech_twin results/kamech_twin [--rasters]
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

import numpy as np
import pandas as pd

#: Column or row labels that measure the run, not the science (compared never).
RUN_MEASURES = re.compile(r"(?:^|_|\s)(?:time|seconds|wall|cpu|memory|mem_|mb|cells_per_s|per_min|per_s|speed|threads)"
                          r"|_s$|\(s\)|elapsed|extrapolated|peak", re.I)


def _drop_run_measures(df: pd.DataFrame) -> pd.DataFrame:
    cols = [c for c in df.columns if not RUN_MEASURES.search(str(c))]
    df = df[cols]
    if len(df.columns) and not pd.api.types.is_numeric_dtype(df.dtypes.iloc[0]):
        keep = ~df.iloc[:, 0].astype(str).str.contains(RUN_MEASURES)
        df = df[keep.to_numpy()]
    return df.reset_index(drop=True)


def compare_tables(before: Path, after: Path) -> list[str]:
    """Names of the CSVs that differ (or are missing) between two results folders."""
    problems = []
    for a in sorted(before.rglob("*.csv")):
        rel = a.relative_to(before)
        b = after / rel
        if not b.exists():
            problems.append(f"{rel}: missing after")
            continue
        da, db = _drop_run_measures(pd.read_csv(a)), _drop_run_measures(pd.read_csv(b))
        if list(da.columns) != list(db.columns) or da.shape != db.shape:
            problems.append(f"{rel}: shape/columns {da.shape} vs {db.shape}")
            continue
        if not da.equals(db):
            diff = (da != db) & ~(da.isna() & db.isna())
            r, c = np.argwhere(diff.to_numpy())[0]
            problems.append(f"{rel}: first difference row {r} column {da.columns[c]!r}: {da.iat[r, c]!r} vs {db.iat[r, c]!r}")
    return problems


def compare_rasters(before: Path, after: Path) -> list[str]:
    """Names of GeoTIFFs whose values differ between two results folders."""
    import rasterio

    problems = []
    for a in sorted(before.rglob("*.tif")):
        rel = a.relative_to(before)
        b = after / rel
        if not b.exists():
            problems.append(f"{rel}: missing after")
            continue
        with rasterio.open(a) as sa, rasterio.open(b) as sb:
            x, y = sa.read(), sb.read()
            if x.shape != y.shape or sa.transform != sb.transform or not np.array_equal(x, y, equal_nan=x.dtype.kind == "f"):
                problems.append(f"{rel}: values or grid differ")
    return problems


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("before", type=Path)
    ap.add_argument("after", type=Path)
    ap.add_argument("--rasters", action="store_true", help="also compare every GeoTIFF cell by cell")
    args = ap.parse_args()
    n = len(list(args.before.rglob("*.csv")))
    problems = compare_tables(args.before, args.after)
    if args.rasters:
        problems += compare_rasters(args.before, args.after)
    for p in problems:
        print("DIFFERS", p)
    print(f"{n} tables compared, {len(problems)} differ")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
