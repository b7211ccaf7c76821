"""The tiled gully rules give the untiled products (issue 21): the tiny twin mapped both ways.

Runs the gully map of ``config/sites/tiny_twin.yaml`` twice through Snakemake, on the
truth-plus-noise stand-in DEM (``gully.dem: truth_plus_noise``: no SfM, a minute on 2
cores): once untiled (the site as it is) and once with a ``tiling:`` section, so that the
depression fill runs as per-tile jobs + merge + mosaic. Then compares every gully table and
raster cell by cell (``benchmarks/compare_runs.py``) and lists the tile jobs Snakemake ran.

    .venv/bin/python benchmarks/tiled_rules_check.py [--tile-m 60] [--cores 2]

Exit status 0 when the two runs' gully products are identical.
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))

from compare_runs import compare_rasters, compare_tables  # noqa: E402

SITE = REPO / "config/sites/tiny_twin.yaml"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tile-m", type=float, default=60.0, help="tile side (m); 60 m on the 200 m tiny twin = 4 x 4 tiles")
    ap.add_argument("--cores", type=int, default=2)
    ap.add_argument("--out", type=Path, default=REPO / "results/tiled_rules_check")
    args = ap.parse_args()
    out = args.out.resolve()
    out.mkdir(parents=True, exist_ok=True)
    name = yaml.safe_load(SITE.read_text())["site"]["name"]
    common = {"gully": {"dem": "truth_plus_noise"}}
    (out / "untiled.yaml").write_text(yaml.safe_dump(common))
    (out / "tiled.yaml").write_text(yaml.safe_dump({**common, "tiling": {"tile_m": args.tile_m, "extent": None}}))
    env = dict(os.environ, PYTHONPATH=f"{REPO / 'src'}{os.pathsep}{os.environ.get('PYTHONPATH', '')}")
    for run in ("untiled", "tiled"):
        target = out / run / name / "gully/gully_summary.csv"
        cmd = [str(REPO / ".venv/bin/snakemake"), "--cores", str(args.cores), "--configfile", str(SITE), str(out / f"{run}.yaml"),
               "--config", f"results_dir={out / run}", "--", str(target), str(out / run / name / "gully/gully_sensitivity.csv")]
        with open(out / f"{run}.log", "w") as fh:
            rc = subprocess.call(cmd, cwd=REPO, stdout=fh, stderr=subprocess.STDOUT, env=env)
        if rc:
            print(f"{run} run failed: see {out / f'{run}.log'}")
            return 1
    log = (out / "tiled.log").read_text()
    jobs = re.findall(r"^(?:local)?rule (gully_\w+):", log, flags=re.M)
    print("tiled run's gully jobs:", {j: jobs.count(j) for j in sorted(set(jobs))})
    a, b = out / "untiled" / name / "gully", out / "tiled" / name / "gully"
    problems = compare_tables(a, b) + [p for p in compare_rasters(a, b) if not p.startswith("tiles/")]
    for p in problems:
        print("DIFFERS", p)
    n_t, n_r = len(list(a.rglob("*.csv"))), len(list(a.rglob("*.tif")))
    print(f"{n_t} tables and {n_r} rasters compared, {len(problems)} differ")
    return 1 if problems or "gully_fill_tile" not in jobs else 0


if __name__ == "__main__":
    sys.exit(main())
