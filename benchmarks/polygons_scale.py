"""Cost of each step of the polygons stage at the full Kamech size (issue 21): time and peak memory.

Builds a DSM of the full site's size (``config/sites/kamech_full.yaml``: 2120 x 1500 m at
0.2 m, 79.5 M cells; 12.7 M cells at the stage's 0.5 m) by mirroring a DSM of the default
twin (``--dsm``, e.g. a copy of ``results/kamech_twin/dense/dsm.tif``) over that extent, and
runs :func:`kitegully.polygons.stage.measure_polygons` on it with the full site's
parameters. Every phase function the stage calls is wrapped so that its wall time and the
process's peak resident memory while it ran are recorded (a thread samples
``/proc/self/statm`` every 20 ms). Writes ``--out`` (CSV: step, calls, wall and CPU seconds,
peak RSS MB; on a shared machine the CPU seconds are the load-independent measure) and prints it.

    nice -n 15 .venv/bin/python benchmarks/polygons_scale.py --dsm results/kamech_twin/dense/dsm.tif \
        [--scale 1.0] [--out results/polygons_scale.csv]

``--scale`` < 1 shrinks the extent (both sides by its square root) for a quick check.
"""

from __future__ import annotations

import argparse
import functools
import os
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pandas as pd

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "src"))

from kitegully.config import load_yaml  # noqa: E402
from kitegully.io.raster import GridSpec, read_raster  # noqa: E402

PAGE = os.sysconf("SC_PAGE_SIZE")


class Sampler(threading.Thread):
    """Peak RSS (MB) of this process since the last :meth:`mark`."""

    def __init__(self) -> None:
        super().__init__(daemon=True)
        self.peak = 0.0
        self.stop = False

    @staticmethod
    def rss() -> float:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * PAGE / 2**20

    def run(self) -> None:
        while not self.stop:
            self.peak = max(self.peak, self.rss())
            time.sleep(0.02)


SAMPLER = Sampler()
ROWS: dict[str, list] = {}


def wrap(module, name: str, label: str | None = None) -> None:
    """Replace ``module.name`` by a wrapper that records calls, time and peak RSS."""
    fn = getattr(module, name)
    label = label or name

    @functools.wraps(fn)
    def inner(*a, **k):
        before = SAMPLER.peak
        SAMPLER.peak = SAMPLER.rss()
        t, tc = time.perf_counter(), time.process_time()
        try:
            return fn(*a, **k)
        finally:
            dt, dc = time.perf_counter() - t, time.process_time() - tc
            row = ROWS.setdefault(label, [0, 0.0, 0.0, 0.0])
            row[0] += 1
            row[1] += dt
            row[2] += dc
            row[3] = max(row[3], SAMPLER.peak, SAMPLER.rss())
            SAMPLER.peak = max(before, SAMPLER.peak)

    setattr(module, name, inner)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dsm", type=Path, required=True, help="a default-twin DSM (0.2 m) to mirror over the full extent")
    ap.add_argument("--scale", type=float, default=1.0, help="area fraction of the full site")
    ap.add_argument("--out", type=Path, default=REPO / "results/polygons_scale.csv")
    ap.add_argument("--tiles", action="store_true", help="then measure the polygons again per tile of kamech_full's tiling "
                    "(kitegully.polygons.tiles, in this process) and compare with the whole-grid morphometry")
    args = ap.parse_args()
    full = load_yaml(REPO / "config/sites/kamech_full.yaml")
    ext = full["twin"]["extent"]
    z0, g0 = read_raster(args.dsm)
    f = np.sqrt(args.scale)
    h = int(round(ext["height_m"] * f / g0.cell))
    w = int(round(ext["width_m"] * f / g0.cell))
    SAMPLER.start()
    t = time.perf_counter()
    z = np.pad(np.asarray(z0, np.float32), ((0, max(0, h - z0.shape[0])), (0, max(0, w - z0.shape[1]))), mode="symmetric")[:h, :w]
    z = np.ascontiguousarray(z)
    del z0
    grid = GridSpec(g0.x0, g0.y0, g0.cell, w, h, g0.crs)
    print(f"input DSM {h} x {w} = {h * w / 1e6:.1f} M cells at {g0.cell} m ({time.perf_counter() - t:.1f} s to build), RSS {Sampler.rss():.0f} MB")

    import kitegully.polygons.conditioning as cond
    import kitegully.polygons.stage as stage
    import kitegully.polygons.thalweg as thal

    # inner steps first (they are looked up in their own modules), then the stage's phase calls
    wrap(thal, "priority_flood_fill", "  TCI: epsilon fill")
    wrap(thal, "_mfd", "  TCI: MFD routing")
    wrap(thal.np, "argsort", "  np.argsort (all calls)")
    wrap(cond, "priority_flood_fill", "  conditioning: priority flood")
    for name in ("prepare_dem", "detect_breaklines", "skeleton_paths", "topographic_convergence_index", "thalweg_lines",
                 "transect_stations", "make_transects", "clip_transects", "rasterize_lines", "barrier_mask", "fill_depth",
                 "low_sides", "gully_mask", "polygons_from_labels", "measure_sections"):
        wrap(stage, name)
    params = stage.PolygonParams.from_config(full["polygons"])
    t, tc = time.perf_counter(), time.process_time()
    rss0 = Sampler.rss()
    res = stage.measure_polygons(z, grid, params)
    total, total_cpu = time.perf_counter() - t, time.process_time() - tc
    rows = [(k, v[0], round(v[1], 2), round(v[2], 2), round(v[3])) for k, v in ROWS.items()]
    rows.append(("measure_polygons (total)", 1, round(total, 2), round(total_cpu, 2), round(max(r[4] for r in rows))))
    df = pd.DataFrame(rows, columns=["step", "calls", "seconds", "cpu_seconds", "peak_rss_MB"])
    args.out.parent.mkdir(parents=True, exist_ok=True)
    df.to_csv(args.out, index=False)
    print(f"stage grid {res.grid.height} x {res.grid.width} = {res.grid.height * res.grid.width / 1e6:.2f} M cells; "
          f"RSS before the stage {rss0:.0f} MB (input DSM held)")
    print(df.to_string(index=False))
    print("phase timings of the stage:", {k: round(v, 1) for k, v in res.timings_s.items()})
    print(f"polygons t=0.5: {len(res.polygons[params.morph_threshold_m])}, sections {len(res.sections)}")
    if args.tiles:
        from kitegully.polygons.tiles import measure_tile, merge_morphometry
        from kitegully.terrain.tiling import TilingParams

        tiling = TilingParams(float(full["tiling"]["tile_m"]), w * g0.cell, h * g0.cell)
        tiles = tiling.tiles(res.grid.shape)
        arrays = {"labels": res.labels[params.morph_threshold_m], "dem": res.dem, "level": res.level, "rims": res.rims}
        parts, cpu = [], []
        for t in tiles:
            tc = time.process_time()
            parts.append(measure_tile(res.polygons[params.morph_threshold_m], res.grid, t,
                                      lambda k, r0, c0, hh, ww: arrays[k][r0:r0 + hh, c0:c0 + ww], params, tiles))
            cpu.append(time.process_time() - tc)
        axes, sections, morph = merge_morphometry(parts, res.grid.crs)
        same = (morph.equals(res.morphometry) and sections.drop(columns="geometry").equals(res.sections.drop(columns="geometry"))
                and all(a.equals_exact(b, 0.0) for a, b in zip(sections.geometry, res.sections.geometry))
                and all(a.equals_exact(b, 0.0) for a, b in zip(axes.geometry, res.axes.geometry)))
        print(f"tiled morphometry, {len(tiles)} tiles: CPU sum {sum(cpu):.1f} s, largest tile {max(cpu):.1f} s, "
              f"per tile {[round(c, 1) for c in cpu]}; identical to the whole grid: {same}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
