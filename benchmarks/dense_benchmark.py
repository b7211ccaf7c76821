"""Dense matching benchmark: cells per second and peak memory, extrapolated to Kamech.

Renders a synthetic block (tests/dense_synthetic.py: exact ray casting of a textured
slope) of ``--views`` × ``--views`` nadir images, matches grids of growing size in fresh
subprocesses (so the peak resident memory of each run is its own), and extrapolates the
time and memory to 3.18 km² at 0.2 m (Feurer et al. 2018). Writes a Markdown table to
``benchmarks/out/dense_benchmark.md``.

Usage: .venv/bin/python benchmarks/dense_benchmark.py [--threads 2] [--views 5]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

CHILD = r"""
import json, resource, sys, time
sys.path.insert(0, "tests")
import numba, numpy as np
import dense_synthetic as ds
from kitegully.dense.matching import MatchParams
from kitegully.dense.surface import dense_surface
from kitegully.io.raster import GridSpec
from kitegully.seeds import rng_for
a = json.loads(sys.argv[1])
numba.set_num_threads(a["threads"])
n = a["views"]
spacing = (8.0, 6.0)
surface = ds.slope(gx=0.2, gy=-0.1)
views, imgs, _ = ds.block(surface, rng_for(2018, "benchmark", "dense"), extent=12.0, height_m=40.0, f=800.0,
                          width=640, height=480, spacing=spacing, grid=(n, n))
cell = 0.1
side = a["side_cells"]
grid = GridSpec(-side * cell / 2, side * cell / 2, cell, side, side, "EPSG:32632")
import yaml
# the default site's matcher settings (levels, window, passes, thresholds), so the rate is the stage's
p = MatchParams.from_config(yaml.safe_load(open("config/sites/kamech_twin.yaml", encoding="utf-8"))["dense"]["matching"])
dense_surface(views, GridSpec(-3.2, 3.2, cell, 64, 64, "EPSG:32632"), p, 64, 16, arrays=imgs)  # JIT warm-up
t = time.perf_counter()
res = dense_surface(views, grid, p, a["tile"], 16, arrays=imgs)
dt = time.perf_counter() - t
xs, ys = grid.cell_centres()
e = res.dsm - surface(xs[None, :], ys[:, None])
img_mb = sum(i.nbytes for i in imgs) / 2**20
print(json.dumps(dict(cells=side * side, seconds=dt, cells_per_s=side * side / dt,
                      peak_mb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, images_mb=img_mb,
                      coverage=res.coverage(), sd_m=float(np.nanstd(e)), median_views=float(np.median(res.nviews)))))
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--views", type=int, default=5)
    ap.add_argument("--sides", type=int, nargs="+", default=[160, 320])
    ap.add_argument("--tile", type=int, default=128)
    args = ap.parse_args()
    rows = []
    for side in args.sides:
        a = dict(threads=args.threads, views=args.views, side_cells=side, tile=args.tile)
        out = subprocess.run([sys.executable, "-c", CHILD, json.dumps(a)], cwd=REPO, capture_output=True, text=True)
        if out.returncode:
            sys.exit(out.stderr[-3000:])
        r = json.loads(out.stdout.strip().splitlines()[-1])
        r["side_cells"] = side
        rows.append(r)
        print(r, flush=True)
    # memory model: fixed part (interpreter, numba, images, tile work) + 12 bytes per output cell
    kam_cells = 3.18e6 / 0.2**2
    rate = rows[-1]["cells_per_s"]
    fixed = rows[0]["peak_mb"] - rows[0]["cells"] * 12 / 2**20
    lines = [
        "# Dense matching benchmark",
        "",
        f"Synthetic block of {args.views}x{args.views} nadir views (640x480 px, GSD 0.05 m, H/B ~2.7), DSM cell 0.1 m,",
        f"tiles of {args.tile} cells + 16 overlap, {args.threads} threads. Timings on a shared machine.",
        "",
        "| grid cells | seconds | cells/s | peak RSS (MB) | coverage | SD vs truth (m) | median usable views |",
        "|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        lines.append(f"| {r['cells']} | {r['seconds']:.1f} | {r['cells_per_s']:.0f} | {r['peak_mb']:.0f} | "
                     f"{r['coverage']:.3f} | {r['sd_m']:.3f} | {r['median_views']:.0f} |")
    lines += [
        "",
        f"Extrapolation to 3.18 km2 at 0.2 m ({kam_cells / 1e6:.1f} M cells) at {rate:.0f} cells/s: "
        f"{kam_cells / rate / 3600:.2f} h on {args.threads} threads; memory ~ {fixed:.0f} MB fixed (tile work, "
        f"image cache) + 12 B/cell of outputs = {(fixed + kam_cells * 12 / 2**20) / 1024:.1f} GB.",
        "Matching time scales with cells x usable views per cell; the real flight's view count per cell sets the rate.",
    ]
    out = REPO / "benchmarks" / "out" / "dense_benchmark.md"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text("\n".join(lines) + "\n", encoding="utf-8")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
