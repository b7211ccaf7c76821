"""Benchmark of the twin generator: default site (epoch 1, with texture) and a full
Kamech-sized DTM (3.18 km2 at 0.2 m, ~80 M cells; DTM, DSM, land cover, survey, vectors;
texture skipped unless --full-texture). Each case runs in a child process so its peak
memory (ru_maxrss) is measured on its own. Prints a Markdown table.

    .venv/bin/python benchmarks/twin_benchmark.py [--threads 2] [--skip-full] [--full-texture]
"""

from __future__ import annotations

import argparse
import copy
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "src"))

CHILD = r"""
import json, sys, numba
from kitegully.twin import TwinParams, build_site, generate_epoch
a = json.loads(sys.argv[1])
numba.set_num_threads(a["threads"])
site = build_site(TwinParams.from_config(a["tw"]), a["crs"], a["seed"], epoch=1)
r = generate_epoch(site, a["out"], texture=a["texture"])
print(json.dumps(r))
"""


def run_case(name: str, tw: dict, crs: str, seed: int, threads: int, texture: bool) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        arg = json.dumps({"tw": tw, "crs": crs, "seed": seed, "threads": threads, "out": tmp, "texture": texture})
        before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
        t0 = time.perf_counter()
        proc = subprocess.run([sys.executable, "-c", CHILD, arg], capture_output=True, text=True, cwd=REPO)
        wall = time.perf_counter() - t0
        if proc.returncode != 0:
            raise RuntimeError(f"{name} failed:\n{proc.stderr[-3000:]}")
        peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
        r = json.loads(proc.stdout.strip().splitlines()[-1])
    e = tw["extent"]
    cells = round(e["width_m"] / tw["dem_cell_m"]) * round(e["height_m"] / tw["dem_cell_m"])
    return {"case": name, "area_km2": e["width_m"] * e["height_m"] / 1e6, "dem_cells_M": cells / 1e6,
            "texture": f"{tw['texture_cell_m']} m" if texture else "no", "wall_s": wall, "terrain_s": r["terrain_s"],
            "texture_s": r["texture_s"], "peak_rss_GB": max(peak, before) / 1e6 if peak > before else float("nan")}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--skip-full", action="store_true")
    ap.add_argument("--full-texture", action="store_true")
    a = ap.parse_args()
    from kitegully.config import load_yaml

    site = load_yaml(REPO / "config/sites/kamech_twin.yaml")
    tw, crs, seed = site["twin"], site["site"]["crs"], site["seed"]
    rows = [run_case("default site (epoch 1)", tw, crs, seed, a.threads, True)]
    if not a.skip_full:
        full = copy.deepcopy(tw)
        full["extent"].update(width_m=2000.0, height_m=1590.0)  # 3.18 km2 [P]
        rows.append(run_case("full Kamech extent (epoch 1)", full, crs, seed, a.threads, a.full_texture))
    cols = list(rows[0])
    print("| " + " | ".join(cols) + " |")
    print("|" + "---|" * len(cols))
    for r in rows:
        print("| " + " | ".join(f"{r[c]:.2f}" if isinstance(r[c], float) else str(r[c]) for c in cols) + " |")


if __name__ == "__main__":
    main()
