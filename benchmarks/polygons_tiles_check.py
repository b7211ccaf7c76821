"""The tiled polygons rules give the untiled products (issue 21): the default site's polygons both ways.

Runs the polygons stage of ``config/sites/kamech_twin.yaml`` twice through Snakemake on a
given DSM (``--dsm``, e.g. a copy of ``results/kamech_twin/dense/dsm.tif``, passed as
``polygons.dem_file`` so that no other stage runs): once untiled (one ``polygons_map`` job)
and once with a ``tiling:`` section (``--tile-m``, 200 m = 2 x 3 tiles on the 600 x 400 m
site), so that step 6 runs as ``polygons_morph_tile`` jobs + ``polygons_morph_merge``. Then
compares every table cell by cell (``benchmarks/compare_runs.py``; run-time rows skipped) and
the medial axes and cross-sections vertex by vertex, and lists the jobs each run ran.

    nice -n 15 .venv/bin/python benchmarks/polygons_tiles_check.py --dsm results/kt_dsm.tif [--tile-m 200] [--cores 2]

Exit status 0 when the two runs' products agree.
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import geopandas as gpd
import yaml

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))

from compare_runs import compare_tables  # noqa: E402

SITE = REPO / "config/sites/kamech_twin.yaml"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dsm", type=Path, required=True, help="the DSM the polygons are mapped on")
    ap.add_argument("--tile-m", type=float, default=200.0)
    ap.add_argument("--cores", type=int, default=2)
    ap.add_argument("--out", type=Path, default=REPO / "results/polygons_tiles_check")
    args = ap.parse_args()
    out = args.out.resolve()
    name = yaml.safe_load(SITE.read_text())["site"]["name"]
    common = {"polygons": {"dem_file": str(args.dsm.resolve())}}
    (out).mkdir(parents=True, exist_ok=True)
    (out / "untiled.yaml").write_text(yaml.safe_dump(common))
    (out / "tiled.yaml").write_text(yaml.safe_dump({**common, "tiling": {"tile_m": args.tile_m, "extent": None}}))
    env = dict(os.environ, PYTHONPATH=f"{REPO / 'src'}{os.pathsep}{os.environ.get('PYTHONPATH', '')}")
    products = ("polygons_summary.csv", "morphometry.csv", "medial_axes.gpkg", "cross_sections.gpkg")
    for run in ("untiled", "tiled"):
        shutil.rmtree(out / run, ignore_errors=True)
        targets = [str(out / run / name / "polygons" / f) for f in products]
        cmd = [str(REPO / ".venv/bin/snakemake"), "--cores", str(args.cores), "--configfile", str(SITE), str(out / f"{run}.yaml"),
               "--config", f"results_dir={out / run}", "--", *targets]
        t = time.perf_counter()
        with open(out / f"{run}.log", "w") as fh:
            rc = subprocess.call(cmd, cwd=REPO, stdout=fh, stderr=subprocess.STDOUT, env=env)
        if rc:
            print(f"{run} run failed: see {out / f'{run}.log'}")
            return 1
        jobs = re.findall(r"^(?:local)?rule (polygons_\w+):", (out / f"{run}.log").read_text(), flags=re.M)
        print(f"{run}: {time.perf_counter() - t:.0f} s wall, jobs {dict(sorted((j, jobs.count(j)) for j in set(jobs)))}")
    a, b = out / "untiled" / name / "polygons", out / "tiled" / name / "polygons"
    problems = [p for p in compare_tables(a, b) if not p.startswith("tiles/")]
    for f in ("medial_axes.gpkg", "cross_sections.gpkg"):
        ga, gb = gpd.read_file(a / f), gpd.read_file(b / f)
        same = len(ga) == len(gb) and ga.drop(columns="geometry").equals(gb.drop(columns="geometry")) and \
            all(x.equals_exact(y, 1e-9) for x, y in zip(ga.geometry, gb.geometry))
        print(f"{f}: {len(ga)} vs {len(gb)} features, {'identical' if same else 'DIFFER'}")
        if not same:
            problems.append(f)
    for p in problems:
        print("DIFFERS", p)
    print(f"{len(list(a.glob('*.csv')))} tables compared, {len(problems)} differ")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
