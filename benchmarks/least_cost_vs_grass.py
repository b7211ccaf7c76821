#!/usr/bin/env python
"""Least-cost drainage directions against GRASS GIS ``r.watershed`` (issue 21, session 20).

``kitegully.terrain.least_cost.least_cost_directions`` (``gully.flat_routing: least_cost``)
follows the least-cost search of ``r.watershed`` (Metz, Mitasova & Harmon 2011): cells
visited from the outlets in order of their own elevation, each draining to the steepest of its
neighbours visited before it. This script runs both on the same unfilled DEM (the gully
benchmark's synthetic catchment with meandering gullies, closed pits and rough noise) and
reports

* wall time of ours (median of ``--runs`` after a compile run) and of ``r.watershed -s``
  (single flow direction, inside GRASS, import and export excluded); ``r.watershed`` also
  accumulates flow in the same call, which ours does not, so the ratio favours ours by that
  step's cost;
* agreement: the share of inner cells whose D8 direction is the same in both, overall and
  on cells that the ε = 0 priority-flood fill raises (inside depressions, where the two rules
  of crossing a depression matter).

Debian ``grass-core`` is installed with apt-get on first use (as ``benchmarks/gully_benchmark.py``
does); without apt the GRASS half is skipped with a message. Writes
``results/benchmarks/least_cost_vs_grass.md``.

    .venv/bin/python benchmarks/least_cost_vs_grass.py [--side 2000] [--runs 3]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))

from gully_benchmark import CRS, ensure_grass, grass_timed, synthetic_catchment  # noqa: E402

from kitegully.io.raster import GridSpec, write_raster  # noqa: E402
from kitegully.terrain.fill import priority_flood_fill  # noqa: E402
from kitegully.terrain.least_cost import least_cost_directions  # noqa: E402

CELL = 0.2
#: r.watershed drainage value v points 45·v degrees counter-clockwise from east (1 NE … 8 E);
#: our codes index kitegully.terrain.flow.D8_OFFSETS (NW, N, NE, W, E, SW, S, SE).
GRASS_TO_D8 = np.array([255, 2, 1, 0, 3, 5, 6, 7, 4], dtype=np.uint8)


def grass_watershed(grass: str, tif: Path, work: Path) -> tuple[float, np.ndarray] | None:
    """``r.watershed -s`` on ``tif``: (wall seconds of the call, drainage as our D8 codes, 255 = none)."""
    g = grass_timed(grass, tif, work, "r.watershed -s elevation=dem drainage=drain", "drain", "Int16")
    if g is None:
        return None
    import rasterio

    with rasterio.open(g[1]) as src:
        v = src.read(1).astype(np.int64)
    codes = np.full(v.shape, 255, dtype=np.uint8)
    ok = (v >= 1) & (v <= 8)  # negative: flows out of the region; 0 or nodata: none
    codes[ok] = GRASS_TO_D8[v[ok]]
    return g[0], codes


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--side", type=int, default=2000, help="DEM side in cells (default 2000: 4 M cells)")
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--out", default=str(REPO / "results/benchmarks/least_cost_vs_grass.md"))
    a = ap.parse_args()
    z = synthetic_catchment(a.side, CELL)[0]
    least_cost_directions(z[:64, :64])  # compile
    times = []
    for _ in range(a.runs):
        t0 = time.perf_counter()
        ours, n_uphill = least_cost_directions(z)
        times.append(time.perf_counter() - t0)
    t_ours = float(np.median(times))
    filled, _ = priority_flood_fill(z, 0.0)
    raised = filled > z.astype(np.float64) + 1e-9
    inner = np.zeros(z.shape, bool)
    inner[1:-1, 1:-1] = True
    rows = [("DEM", f"{a.side} x {a.side} = {a.side * a.side / 1e6:.1f} M cells, cell {CELL} m, unfilled "
             f"({int(raised.sum())} cells below their spill level)"),
            ("ours: least_cost_directions wall (s), median of runs", f"{t_ours:.2f} ({', '.join(f'{t:.2f}' for t in times)})"),
            ("ours: cells draining to a neighbour not below them", str(n_uphill))]
    grass = ensure_grass()
    if grass:
        with tempfile.TemporaryDirectory() as tmp:
            tif = Path(tmp) / "dem.tif"
            grid = GridSpec(500000.0, 4000000.0 + a.side * CELL, CELL, a.side, a.side, CRS)
            write_raster(tif, z, grid)
            g = grass_watershed(grass, tif, Path(tmp))
        if g is not None:
            t_g, theirs = g
            both = inner & (ours != 255) & (theirs != 255)
            same = ours == theirs
            rows += [("GRASS r.watershed -s wall (s; accumulation included)", f"{t_g:.2f}"),
                     ("speed ratio GRASS / ours", f"{t_g / t_ours:.1f} x"),
                     ("inner cells with a direction in both", str(int(both.sum()))),
                     ("same D8 direction, all inner cells (%)", f"{100 * same[both].mean():.2f}"),
                     ("same D8 direction, cells inside depressions (%)",
                      f"{100 * same[both & raised].mean():.2f} of {int((both & raised).sum())}"),
                     ("same D8 direction, cells outside depressions (%)", f"{100 * same[both & ~raised].mean():.2f}")]
    text = "# Least-cost drainage directions: ours against GRASS r.watershed\n\n| item | value |\n|---|---|\n"
    text += "".join(f"| {k} | {v} |\n" for k, v in rows)
    print(text)
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    Path(a.out).write_text(text)


if __name__ == "__main__":
    main()
