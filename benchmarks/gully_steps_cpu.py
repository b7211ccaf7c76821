#!/usr/bin/env python
"""CPU time of the gully stage's heavy steps, one thread, former revision against the working tree.

Each revision's steps run in a child process importing its own ``src`` (the former one from
``git archive``), on the same synthetic DEM as ``gully_benchmark.py`` (default 20 M cells),
alternated ``--rounds`` times; CPU = user + system time of the child around each step. The
children set the allocator as the gully rule scripts of that revision do
(:func:`kitegully.memory.keep_freed_memory` where it exists).

Usage::

    PYTHONPATH=src .venv/bin/python benchmarks/gully_steps_cpu.py --cells 20e6 --rounds 2

Prints a Markdown table (former / new per round, and the ratio of the sums).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
SITE = REPO / "config" / "sites" / "kamech_full.yaml"

CHILD = r'''
import json, resource, sys
src, d, site = sys.argv[1], sys.argv[2], sys.argv[3]
sys.path.insert(0, src)
try:
    from kitegully.memory import keep_freed_memory
    keep_freed_memory()
except ImportError:
    pass
import numpy as np, yaml
from kitegully.io.raster import read_raster, write_raster
from kitegully.gully.params import GullyParams
from kitegully.gully.surface import tracing_surface
from kitegully.gully.depth import depth_map
from kitegully.gully.patches import depth_patches
from kitegully.terrain.fill import priority_flood_fill
from kitegully.terrain.flats import flow_directions
def cpu():
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime
T = {}
def tm(name, f, *a, **k):
    t0 = cpu(); r = f(*a, **k); T[name] = T.get(name, 0.0) + cpu() - t0
    return r
g = yaml.safe_load(open(site))["gully"]; g["crowns"] = {"enabled": False}
p = GullyParams.from_config(g)
dem, grid = read_raster(d + "/dem.tif")
small = np.ascontiguousarray(dem[:400, :400])  # numba compilation / cache load outside the timing
flow_directions(priority_flood_fill(small.astype(np.float64), 0.0)[0])
depth_patches(depth_map(small, grid.cell, g["sigma_m"])[1], grid.cell, 0.25, 1.0, 8)
zh, zt, nh = tm("tracing surface", tracing_surface, dem, grid, p, 1)
fz, nr = tm("fill", priority_flood_fill, zt, 0.0); del zt, zh
tm("flow directions", flow_directions, fz); del fz
s, dd = tm("depth map (map sigma)", depth_map, dem, grid.cell, g["sigma_m"], g["truncate_sigmas"], 1)
tm("patches (map)", depth_patches, dd, grid.cell, g["depth_threshold_m"], g["min_patch_volume_m3"], g["connectivity"])
def write():
    write_raster(d + "/steps_depth.tif", dd, grid); write_raster(d + "/steps_smoothed.tif", s, grid)
tm("writing depth + smoothed", write); del s, dd
for sg in g["sensitivity"]["sigmas_m"]:
    s, dd = tm("sensitivity depth maps", depth_map, dem, grid.cell, sg, g["truncate_sigmas"], 1); del s
    for thr in g["sensitivity"]["depth_thresholds_m"]:
        tm("sensitivity patch labellings", depth_patches, dd, grid.cell, thr, g["min_patch_volume_m3"], g["connectivity"])
    del dd
print(json.dumps(T))
'''


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cells", type=float, default=20e6)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--against", default="969daf7", help="former git revision (default: main at session-9 end)")
    args = ap.parse_args()
    sys.path.insert(0, str(REPO / "src"))
    sys.path.insert(0, str(REPO / "benchmarks"))
    from gully_benchmark import CRS, synthetic_catchment

    from kitegully.io.raster import GridSpec, write_raster

    side = int(round(np.sqrt(args.cells)))
    with tempfile.TemporaryDirectory(prefix="gully_steps_") as tmp:
        z = synthetic_catchment(side, 0.2)[0]
        write_raster(Path(tmp) / "dem.tif", z, GridSpec(500000.0, 4100000.0, 0.2, side, side, CRS))
        del z
        arc = subprocess.run(["git", "-C", str(REPO), "archive", args.against, "src"], capture_output=True, check=True)
        (Path(tmp) / "former").mkdir()
        subprocess.run(["tar", "-x", "-C", str(Path(tmp) / "former")], input=arc.stdout, check=True)
        runs = {"former": [], "new": []}
        for _ in range(args.rounds):
            for key, src in (("former", Path(tmp) / "former" / "src"), ("new", REPO / "src")):
                p = subprocess.run([sys.executable, "-c", CHILD, str(src), tmp, str(SITE)], capture_output=True, text=True)
                if p.returncode:
                    raise SystemExit(p.stderr[-3000:])
                runs[key].append(json.loads(p.stdout.strip().splitlines()[-1]))
    print(f"Single-thread CPU (user + sys, s) per step, {side} x {side} cells, former ({args.against}) / new, "
          f"{args.rounds} alternated rounds\n")
    print("| step | former | new | ratio of the sums |\n|---|---:|---:|---:|")
    steps = list(runs["new"][0]) + ["all these steps"]
    for r in runs["former"] + runs["new"]:
        r["all these steps"] = sum(r.values())
    for k in steps:
        f = [r[k] for r in runs["former"]]
        n = [r[k] for r in runs["new"]]
        print(f"| {k} | {' / '.join(f'{v:.2f}' for v in f)} | {' / '.join(f'{v:.2f}' for v in n)} | {sum(f) / sum(n):.2f}x |")


if __name__ == "__main__":
    main()
