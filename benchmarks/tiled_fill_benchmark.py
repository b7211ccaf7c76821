#!/usr/bin/env python
"""Benchmark of the tiled Priority-Flood (Barnes 2016) against the untiled fill (issue 21).

Makes a random-fractal DEM (spectral synthesis, power spectrum ∝ f^-β, β = 2.4, float32
GeoTIFF, default 4000 × 4000 cells), then runs each step as its own child process, the
way Snakemake jobs would run it, reading only what the step needs from files:

* ``untiled``: read the whole DEM, ``priority_flood_fill(z, epsilon=0)``;
* ``fill`` per tile: read the tile + 1-cell halo (windowed read), :func:`fill_tile`,
  write the tile's fill/labels and its perimeter summary;
* ``merge``: read all summaries, :func:`merge_tiles`, write the spill elevations;
* ``finalise`` per tile: :func:`finalise_tile`, write the tile's filled cells.

Each child reports its compute time (the fastest of ``--repeat`` calls of the library
function: the machine is shared; not interpreter start, numba
cache loading or file I/O) and its peak RSS (``VmHWM``); a baseline child loads the same
code and opens the DEM but reads no data, so "above baseline" is the job's data. The tiled
result is checked to be equal to the untiled one (bit for bit, -0.0 read as +0.0).

Usage::

    PYTHONPATH=src .venv/bin/python benchmarks/tiled_fill_benchmark.py             # 4000², tiles of 1000
    PYTHONPATH=src .venv/bin/python benchmarks/tiled_fill_benchmark.py --size 1000 --tile 300

Results are printed and written to ``results/benchmarks/tiled_fill_benchmark.md``.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]


def _maxrss_mb() -> float:
    """Peak RSS of this process (VmHWM: unlike ``ru_maxrss`` it is not inherited from
    the parent across fork + exec)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return float(line.split()[1]) / 1024.0
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def fractal_dem(size: int, beta: float = 2.4, relief_m: float = 50.0, seed: int = 0) -> np.ndarray:
    """Random-fractal surface by spectral synthesis (float32, metres)."""
    from kitegully.seeds import rng_for

    rng = rng_for(seed, "benchmarks", "tiled_fill")
    fy = np.fft.fftfreq(size)[:, None]
    fx = np.fft.rfftfreq(size)[None, :]
    f = np.hypot(fy, fx)
    f[0, 0] = 1.0
    amp = f ** (-beta / 2.0)
    amp[0, 0] = 0.0
    spec = amp * np.exp(2j * np.pi * rng.random(amp.shape))
    del amp, f
    z = np.fft.irfft2(spec, s=(size, size))
    del spec
    z = (z - z.min()) / (z.max() - z.min()) * relief_m
    return z.astype(np.float32)


def _write_dem(z: np.ndarray, path: Path) -> None:
    import rasterio
    from rasterio.transform import from_origin

    with rasterio.open(path, "w", driver="GTiff", width=z.shape[1], height=z.shape[0], count=1, dtype="float32",
                       nodata=np.nan, crs="EPSG:32632", transform=from_origin(500000, 4000000, 0.2, 0.2),
                       tiled=True, blockxsize=256, blockysize=256) as dst:
        dst.write(z, 1)


# ----------------------------------------------------------------------------- jobs


def _timed(fn, repeat: int):
    """(result of the last call, fastest wall time of ``repeat`` calls): the machine is shared."""
    best = float("inf")
    res = None
    for _ in range(repeat):
        res = None  # free the previous result first: the peak RSS is that of one call
        t0 = time.perf_counter()
        res = fn()
        best = min(best, time.perf_counter() - t0)
    return res, best


def job(args: argparse.Namespace) -> dict:
    from kitegully.terrain import tiled_fill as tf
    from kitegully.terrain.fill import priority_flood_fill

    work = Path(args.work)
    info = json.loads((work / "grid.json").read_text())
    tiles = {t.name: t for t in tf.tile_grid(tuple(info["shape"]), info["tile"])}
    out: dict = {"job": args.job, "tile": args.name}
    # load the jitted kernels (numba cache) before timing, in every job and the baseline
    zw = np.arange(64, dtype=np.float64).reshape(8, 8) % 7
    priority_flood_fill(zw, epsilon=0.0)
    tf.tiled_priority_flood_fill(zw, 3)
    # and GDAL: open the DEM and read one cell, so the baseline holds the raster library
    tf.read_tile_with_halo(work / "dem.tif", tf.Tile(0, 0, 0, 0, 0, 1, 1))
    if args.job == "baseline":
        pass
    elif args.job == "untiled":
        import rasterio

        with rasterio.open(work / "dem.tif") as src:
            z = src.read(1)
        (w, n), out["seconds"] = _timed(lambda: priority_flood_fill(z, epsilon=0.0), args.repeat)
        out["n_raised"] = n
        np.save(work / "untiled.npy", w)
    elif args.job == "fill":
        t = tiles[args.name]
        zh = tf.read_tile_with_halo(work / "dem.tif", t)
        res, out["seconds"] = _timed(lambda: tf.fill_tile(zh, t), args.repeat)
        out["n_labels"] = res.n_labels
        out["n_edges"] = int(res.edges[0].size)
        res.save(work / f"{t.name}.fill.npz")
        res.summary().save(work / f"{t.name}.summary.npz")
    elif args.job == "merge":
        sums = [tf.TileSummary.load(work / f"{name}.summary.npz") for name in tiles]
        sp, out["seconds"] = _timed(lambda: tf.merge_tiles(sums), args.repeat)
        out["n_nodes"] = int(sp.spill.size)
        out["n_edges"] = int(sum(s.edges[0].size for s in sums))
        sp.save(work / "spill.npz")
    elif args.job == "finalise":
        t = tiles[args.name]
        res = tf.TileFill.load(work / f"{t.name}.fill.npz")
        sp = tf.SpillElevations.load(work / "spill.npz")
        w, out["seconds"] = _timed(lambda: tf.finalise_tile(res, sp), args.repeat)
        np.save(work / f"{t.name}.final.npy", w)
    out["maxrss_mb"] = _maxrss_mb()
    return out


_REPEAT = 3


def _run(work: Path, jobname: str, name: str = "") -> dict:
    cmd = [sys.executable, __file__, "--job", jobname, "--work", str(work), "--name", name, "--repeat", str(_REPEAT)]
    t0 = time.perf_counter()
    p = subprocess.run(cmd, capture_output=True, text=True, cwd=REPO)
    if p.returncode:
        raise RuntimeError(f"{jobname} {name} failed:\n{p.stderr}")
    res = json.loads(p.stdout.strip().splitlines()[-1])
    res["process_s"] = time.perf_counter() - t0
    return res


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--size", type=int, default=4000)
    ap.add_argument("--tile", type=int, default=1000)
    ap.add_argument("--repeat", type=int, default=3, help="time each library call this often, keep the fastest")
    ap.add_argument("--job", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--work", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--name", default="", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.job:
        print(json.dumps(job(args)))
        return
    global _REPEAT
    _REPEAT = args.repeat

    from kitegully.terrain import tiled_fill as tf

    with tempfile.TemporaryDirectory(prefix="tiled_fill_") as tmp:
        work = Path(tmp)
        z = fractal_dem(args.size)
        _write_dem(z, work / "dem.tif")
        (work / "grid.json").write_text(json.dumps({"shape": list(z.shape), "tile": args.tile}))
        del z
        tiles = tf.tile_grid((args.size, args.size), args.tile)
        _run(work, "baseline")  # warms the numba cache
        base = _run(work, "baseline")
        unt = _run(work, "untiled")
        fills = [_run(work, "fill", t.name) for t in tiles]
        merge = _run(work, "merge")
        fins = [_run(work, "finalise", t.name) for t in tiles]
        ref = np.load(work / "untiled.npy")
        out = np.empty_like(ref)
        for t in tiles:
            out[t.r0 : t.r0 + t.h, t.c0 : t.c0 + t.w] = np.load(work / f"{t.name}.final.npy")
        equal = bool(np.array_equal((out + 0.0).view(np.int64), (ref + 0.0).view(np.int64)))
        n_diff = int(np.sum(out != ref))

    b = base["maxrss_mb"]
    tiled_s = sum(f["seconds"] for f in fills) + merge["seconds"] + sum(f["seconds"] for f in fins)
    rows = [
        ("untiled fill (1 job)", unt["seconds"], unt["maxrss_mb"], unt["process_s"]),
        (f"per-tile fill ({len(fills)} jobs; max)", max(f["seconds"] for f in fills),
         max(f["maxrss_mb"] for f in fills), max(f["process_s"] for f in fills)),
        ("merge (1 job)", merge["seconds"], merge["maxrss_mb"], merge["process_s"]),
        (f"finalise ({len(fins)} jobs; max)", max(f["seconds"] for f in fins),
         max(f["maxrss_mb"] for f in fins), max(f["process_s"] for f in fins)),
    ]
    lines = [
        f"# Tiled Priority-Flood vs untiled fill: {args.size} x {args.size} fractal DEM, tiles of {args.tile}",
        "",
        f"Baseline child (interpreter, numpy, jitted kernels, rasterio with the DEM open, no data): peak RSS {b:.0f} MB.",
        "",
        "| step | compute s | peak RSS MB | above baseline MB | process wall s |",
        "|---|---:|---:|---:|---:|",
    ]
    for name, s, rss, ps in rows:
        lines.append(f"| {name} | {s:.2f} | {rss:.0f} | {rss - b:.0f} | {ps:.1f} |")
    lines += [
        "",
        f"Tiled compute total (all jobs in sequence, one core): {tiled_s:.2f} s "
        f"(fill {sum(f['seconds'] for f in fills):.2f}, merge {merge['seconds']:.2f}, "
        f"finalise {sum(f['seconds'] for f in fins):.2f}); untiled {unt['seconds']:.2f} s.",
        f"Labels (graph nodes) {merge['n_nodes']}, in-tile graph edges {merge['n_edges']}; "
        f"cells raised {unt['n_raised']}.",
        f"Tiled == untiled (bit for bit, -0.0 as +0.0): {equal}; cells differing in value: {n_diff}.",
    ]
    text = "\n".join(lines)
    print(text)
    dest = REPO / "results" / "benchmarks"
    dest.mkdir(parents=True, exist_ok=True)
    (dest / "tiled_fill_benchmark.md").write_text(text + "\n")
    if not equal:
        sys.exit(1)


if __name__ == "__main__":
    main()
