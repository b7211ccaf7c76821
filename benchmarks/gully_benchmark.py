#!/usr/bin/env python
"""Benchmark of the gully stage at Kamech scale (issue 7).

Makes a synthetic catchment DEM (default 80 M cells at 0.2 m, about 3.2 km², with carved
V gullies, pits and rough noise), then

1. runs the whole gully stage as its three rules do, each in a child process: mapping
   (read DEM, depth map, patches, filling with flat resolution, tracing, buffer, polygons,
   write rasters and vectors), the sensitivity table (3 σ x 3 thresholds, scored against
   the constructed gully centrelines as reference) and the network validation (footprint,
   paper-protocol reference filter, 3 tolerances x 2 reference sets, Fig. 9b map), and
   reports wall times and peak memory (target: whole stage < 3 min, < 8 GB on 2 cores);
2. times our FFT smoothing against ``scipy.ndimage.gaussian_filter`` (same σ, same
   truncation) on the full DEM and prints the ratio and the largest difference;
3. times our priority-flood filling against GRASS GIS ``r.fill.dir`` (Debian
   ``grass-core``, installed here with apt-get; skipped with a message if apt is
   unavailable) and pysheds (pinned in its own virtual environment; skipped with a
   message if it cannot be installed) on the same tile (default 4 M cells: GRASS's
   iterative filler is far too slow for 80 M), and compares the filled surfaces.

Usage::

    .venv/bin/python benchmarks/gully_benchmark.py                # full benchmark
    .venv/bin/python benchmarks/gully_benchmark.py --cells 4e6    # quick run

Results are printed and written to ``results/benchmarks/gully_benchmark.md``.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
PYSHEDS_PIN = "pysheds==0.5"
# pysheds 0.5 fails to compile under numba 0.68 (itertools.count in a jitted function);
# its venv pins the last numba/numpy pair it works with.
PYSHEDS_VENV_PINS = [PYSHEDS_PIN, "numba==0.61.2", "numpy==2.2.6"]
CRS = "EPSG:32632"
# the children import kitegully from here (``--against`` points them at a former revision)
SRC = os.environ.get("KITEGULLY_BENCH_SRC", str(REPO / "src"))
# main at the end of session 9 (before session 10's CPU work on the gully stage); session 9 compared
# with 55a02f9 (main at session-8 end), session 6 with 3974773 (main at session-5 end, which no longer
# runs the sites' current gully settings)
# Since session 21 (head_snap: posterior) and session 23 (gully.edge_inlets) that revision cannot run the full
# site's gully settings, so by default no former revision is timed: pass --against REV for one that knows them.
FORMER = ""
# the 80 M-cell site of issue 21: its gully settings are the ones timed (the default twin's need
# checkpoints for head_snap: relief and an orthophoto for gully.crowns, which the synthetic DEM has not)
SITE = "kamech_full"


def peak_self_gb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20


# --------------------------------------------------------------------------- synthetic DEM
def synthetic_catchment(side: int, cell: float, seed: int = 2018) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A south-draining catchment with meandering V gullies, closed pits and rough noise.

    Returns the float32 DEM and the head coordinates (x, y relative to the top-left corner).
    """
    import scipy.ndimage as ndi

    rng = np.random.default_rng(seed)
    n_gullies = max(3, side // 400)
    x0 = rng.uniform(0.05, 0.95, n_gullies) * side * cell
    amp = rng.uniform(5, 30, n_gullies)
    wave = rng.uniform(80, 300, n_gullies)
    width = rng.uniform(4, 16, n_gullies)
    depth = rng.uniform(0.8, 2.5, n_gullies)
    start = rng.uniform(0.05, 0.4, n_gullies) * side * cell  # gully head distance from the top
    xs = (np.arange(side, dtype=np.float32) + 0.5) * cell
    z = np.empty((side, side), dtype=np.float32)
    step = 512
    for r0 in range(0, side, step):
        ys = (np.arange(r0, min(side, r0 + step), dtype=np.float32) + 0.5) * cell
        Y, X = np.meshgrid(ys, xs, indexing="ij")
        # slope falling south (y grows southwards) plus broad undulations
        block = 200 - 0.04 * Y + 0.01 * X + 3 * np.sin(X / 400) * np.cos(Y / 550)
        for k in range(n_gullies):
            xc = x0[k] + amp[k] * np.sin(Y / wave[k])
            notch = depth[k] * np.clip(1 - np.abs(X - xc) / (width[k] / 2), 0, None)
            notch *= np.clip((Y - start[k]) / 20.0, 0, 1)  # the gully starts at its head
            block -= notch
        z[r0 : r0 + step] = block
    noise = rng.standard_normal((side, side), dtype=np.float32)
    ndi.gaussian_filter(noise, 2.0, output=noise)
    noise *= np.float32(0.05 / max(float(noise[:1000, :1000].std()), 1e-9))
    z += noise
    # closed pits (0.3-1 m) to fill
    npits = side * side // 20000
    pr = rng.integers(5, side - 5, npits)
    pc = rng.integers(5, side - 5, npits)
    z[pr, pc] -= rng.uniform(0.3, 1.0, npits).astype(np.float32)
    hx = x0 + amp * np.sin(start / wave)
    return z, hx, start, (x0, amp, wave, start)


def centrelines(params, side: int, cell: float, x_origin: float, y_origin: float):
    """The synthetic gullies' centrelines (head to the bottom edge) as LineStrings in map coordinates."""
    from shapely import LineString

    x0, amp, wave, start = params
    lines = []
    for k in range(x0.size):
        y = np.arange(start[k], side * cell, 1.0)
        x = x0[k] + amp[k] * np.sin(y / wave[k])
        lines.append(LineString(np.column_stack([x_origin + x, y_origin - y])))
    return lines


# --------------------------------------------------------------------------- child: whole stage
def site_gully_config() -> dict:
    """The full-size site's (:data:`SITE`) ``gully:`` section: the children run with its rules' settings."""
    import yaml

    g = yaml.safe_load((REPO / "config" / "sites" / f"{SITE}.yaml").read_text())["gully"]
    g["crowns"] = {"enabled": False}  # the synthetic catchment has no orthophoto (gully.crowns needs one)
    # no checkpoints either: the synthetic DEM's stated noise (synthetic_catchment adds 0.05 m) for the incision map
    # that head_snap relief/posterior and edge_inlets read
    g["automatic_heads"] = {**g["automatic_heads"], "dsm_sigma_z_m": 0.05}
    return g


def as_rule_process() -> None:
    """What the gully rule scripts do first in their process: :func:`kitegully.memory.keep_freed_memory`
    where the revision under test has it (session 10 on), so a former revision runs as its rules did."""
    sys.path.insert(0, SRC)
    try:
        from kitegully.memory import keep_freed_memory
    except ImportError:
        return
    keep_freed_memory()


def run_stage(dem_path: str, heads_path: str, out_dir: str, threads: int) -> None:
    """Whole gully mapping chain as the gully_map rule runs it, with the full-size site's (:data:`SITE`)
    ``gully:`` settings (flat resolution, head snapping, tracing surface), in a child process."""
    as_rule_process()
    from kitegully.gully.params import GullyParams
    from kitegully.gully.pipeline import map_gullies, map_raster
    from kitegully.io.raster import read_raster, write_raster
    from kitegully.io.vectors import write_vector

    t0 = time.perf_counter()
    dem, grid = read_raster(dem_path)
    heads = np.load(heads_path)
    t_read = time.perf_counter() - t0
    out = Path(out_dir)
    # the four rasters the gully_map rule writes (session 6 timed depth and map only), the depth
    # rasters as the rule writes them (on_depth: beside the fill where the code knows it)
    g = site_gully_config()
    params = GullyParams.from_config(g)

    def write_depth(s, d):
        write_raster(out / "depth.tif", d, grid)
        write_raster(out / "smoothed.tif", s, grid)

    import inspect

    sig = inspect.signature(map_gullies).parameters
    early = "on_depth" in sig
    kw = {"on_depth": write_depth} if early else {}
    if "incision" in sig:  # as the gully_map rule passes them (head_snap relief/posterior, edge_inlets)
        from kitegully.gully.heads import HeadDetectionParams

        kw["incision"] = HeadDetectionParams.from_config(g["automatic_heads"])
        if "auto_heads" in sig and g.get("heads") in ("automatic", "both"):  # the rule's head detector (session 38)
            kw["auto_heads"] = kw["incision"]
    res = map_gullies(dem, grid, heads[0], heads[1], params, workers=threads, **kw)
    t1 = time.perf_counter()
    if not early:  # a former revision: after the mapping, as its rule did
        write_depth(res.smoothed, res.depth)
    write_raster(out / "gully_map.tif", map_raster(res.gully, np.isfinite(dem)), grid, nodata=255)
    write_raster(out / "gully_map_whole.tif", map_raster(res.gully_whole_patches, np.isfinite(dem)), grid, nodata=255)
    write_vector(res.lines, out / "gully_network.gpkg")
    write_vector(res.extracted_lines, out / "gully_network_mapped.gpkg")
    write_vector(res.polygons, out / "gully_polygons.gpkg")
    res.network.save(out / "network.npz")
    t_write = time.perf_counter() - t1
    print(json.dumps({
        "read_s": t_read, "write_s": t_write, **res.timings_s,
        "network_length_m": float(res.lines["length_m"].sum()), "n_gullies": len(res.polygons),
        "paths_in_pit": res.network.n_paths_not_at_outlet(), "peak_gb": peak_self_gb(),
    }))


def run_sensitivity(dem_path: str, out_dir: str, threads: int) -> None:
    """The gully_sensitivity rule's work (its library function with the full-size site's settings), in a child process."""
    as_rule_process()
    from kitegully.gully.network import GullyNetwork
    from kitegully.gully.params import GullyParams
    from kitegully.gully.sensitivity import gully_sensitivity
    from kitegully.io.raster import read_raster
    from kitegully.io.vectors import read_vector

    from concurrent.futures import ThreadPoolExecutor

    t0 = time.perf_counter()
    with ThreadPoolExecutor(max_workers=1) as pool:  # as the rule reads them
        later = pool.submit(read_raster, Path(out_dir) / "depth.tif")
        dem, grid = read_raster(dem_path)
        depth, _ = later.result()
    net = GullyNetwork.load(Path(out_dir) / "network.npz")
    reference = read_vector(Path(out_dir) / "reference.gpkg")
    g = site_gully_config()
    table = gully_sensitivity(dem, grid, net, depth, GullyParams.from_config(g), g["sensitivity"]["sigmas_m"],
                              g["sensitivity"]["depth_thresholds_m"], g["validation"]["tolerance_m"], reference=reference,
                              workers=threads)
    table.to_csv(Path(out_dir) / "sensitivity.csv", index=False)
    print(json.dumps({"sensitivity_s": time.perf_counter() - t0, "peak_gb": peak_self_gb()}))


def run_validation(dem_path: str, out_dir: str) -> None:
    """The gully_validate rule's work (:func:`kitegully.gully.validation.score_network` with the default
    site's ``gully.validation`` settings, then the Fig. 9b map), in a child process."""
    as_rule_process()
    from kitegully.gully.plots import validation_map
    from kitegully.gully.validation import UNFILTERED, ValidationParams, score_network
    from kitegully.io.figures import save_figure
    from kitegully.io.raster import read_raster
    from kitegully.io.vectors import read_vector

    t = {}
    t0 = time.perf_counter()
    out = Path(out_dir)
    params = ValidationParams.from_config(site_gully_config()["validation"])
    reference = read_vector(out / "reference.gpkg")
    extracted = read_vector(out / "gully_network_mapped.gpkg")
    gully, grid = read_raster(out / "gully_map.tif")
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(max_workers=1) as pool:  # as the rule: the DEM decoded while the network is scored
        later = pool.submit(read_raster, dem_path)
        res = score_network(reference, extracted, gully != 255, grid, params)
        t["score_network_s"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        dem, _ = later.result()
    tol = res.tolerances[(res.tolerances["reference_lines"] == UNFILTERED) & (res.tolerances["category"] == "good_fit")]
    good = dict(zip(tol["tolerance_m"], tol["percent"]))
    fig = validation_map(dem, gully == 1, grid, res.pieces, params.tolerance_m)
    save_figure(fig, out / "validation_map.png")
    t["figure_s"] = time.perf_counter() - t0
    print(json.dumps({**t, "tolerances_m": params.tolerances_m, "good_fit_percent": good, "peak_gb": peak_self_gb()}))


# --------------------------------------------------------------------------- GRASS and pysheds
def ensure_grass() -> str | None:
    """The ``grass`` executable, installing Debian grass-core with apt-get when missing (every
    benchmark that compares with GRASS calls this one); None, with the reason printed, when it
    cannot be installed."""
    grass = shutil.which("grass")
    if grass:
        return grass
    if not shutil.which("apt-get"):
        print("GRASS comparison skipped: apt-get is not available on this machine")
        return None
    print("installing Debian grass-core with apt-get (once) ...", flush=True)
    env = dict(os.environ, DEBIAN_FRONTEND="noninteractive")
    for cmd in (["apt-get", "update", "-qq"], ["apt-get", "install", "-y", "-qq", "--no-install-recommends", "grass-core"]):
        p = subprocess.run(cmd, env=env, capture_output=True, text=True)
        if p.returncode != 0:
            print(f"GRASS comparison skipped: {' '.join(cmd)} failed: {p.stderr.strip()[-300:]}")
            return None
    return shutil.which("grass")


def grass_timed(grass: str, tif: Path, work: Path, command: str, output: str, out_type: str) -> tuple[float, Path] | None:
    """Import ``tif`` as raster ``dem`` into a temporary GRASS location, time ``command`` alone
    (import and export excluded) and export raster ``output`` as GeoTIFF: (seconds, path), or None
    with the error printed when GRASS fails."""
    name = command.split()[0]
    script = work / f"grass_{name}.sh"
    out = work / f"grass_{output}.tif"
    script.write_text(textwrap.dedent(f"""\
        set -e
        r.in.gdal -o input={tif} output=dem --quiet
        g.region raster=dem
        t0=$(date +%s.%N)
        {command} --quiet --overwrite
        t1=$(date +%s.%N)
        echo "GRASSTIME $t0 $t1"
        r.out.gdal input={output} output={out} type={out_type} --quiet --overwrite
        """))
    p = subprocess.run([grass, "--tmp-location", CRS, "--exec", "bash", str(script)], capture_output=True, text=True)
    line = [ln for ln in p.stdout.splitlines() if ln.startswith("GRASSTIME")]
    if p.returncode != 0 or not line:
        print(f"GRASS {name} failed: {p.stderr.strip()[-500:]}")
        return None
    _, a, b = line[0].split()
    return float(b) - float(a), out


def grass_fill(grass: str, tif: Path, work: Path) -> tuple[float, np.ndarray] | None:
    g = grass_timed(grass, tif, work, "r.fill.dir input=dem output=filled direction=dir", "filled", "Float64")
    if g is None:
        return None
    import rasterio

    with rasterio.open(g[1]) as src:
        return g[0], src.read(1)


def ensure_pysheds(venv: Path) -> Path | None:
    py = venv / "bin" / "python"
    check = "import pysheds, numba; assert numba.__version__ == '0.61.2'"
    if py.exists() and subprocess.run([str(py), "-c", check], capture_output=True).returncode == 0:
        return py
    print(f"installing {PYSHEDS_PIN} into its own venv {venv} (once) ...", flush=True)
    p = subprocess.run([sys.executable, "-m", "venv", str(venv)], capture_output=True, text=True)
    if p.returncode == 0:
        p = subprocess.run([str(py), "-m", "pip", "install", "-q", *PYSHEDS_VENV_PINS], capture_output=True, text=True)
    if p.returncode != 0:
        print(f"pysheds comparison skipped: could not install {PYSHEDS_PIN}: {p.stderr.strip()[-300:]}")
        return None
    return py


PYSHEDS_CHILD = """
import sys, time, json, numpy as np
from pysheds.grid import Grid
from pysheds.sview import Raster, ViewFinder
def fill(a):
    vf = ViewFinder(shape=a.shape, nodata=np.nan)
    return Grid(viewfinder=vf).fill_depressions(Raster(np.ascontiguousarray(a), viewfinder=vf))
z = np.load(sys.argv[1])
fill(z[:50, :50])  # warm up before timing
t0 = time.perf_counter()
filled = fill(z)
t1 = time.perf_counter()
np.save(sys.argv[2], np.asarray(filled))
print(json.dumps({"fill_s": t1 - t0}))
"""


# --------------------------------------------------------------------------- main
def peak_rss_children_gb() -> float:
    return resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 2**20


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cells", type=float, default=80e6, help="DEM cells of the whole-stage run (default 80e6)")
    ap.add_argument("--compare-cells", type=float, default=4e6, help="tile cells of the fill comparison (default 4e6)")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--skip-grass", action="store_true")
    ap.add_argument("--skip-pysheds", action="store_true")
    ap.add_argument("--skip-scipy", action="store_true", help="skip the scipy.ndimage.gaussian_filter timing")
    ap.add_argument("--against", default=FORMER, help="git revision whose gully stage and fill are timed beside "
                    "the working tree's (empty string: no comparison)")
    ap.add_argument("--grass-runs", type=int, default=3, help="GRASS r.fill.dir runs (median; default 3)")
    ap.add_argument("--fill-only", action="store_true", help="only the depression-filling comparison (no stage, no smoothing)")
    ap.add_argument("--stage-only", action="store_true", help="only the whole-stage comparison (no smoothing, no fill comparison)")
    ap.add_argument("--rounds", type=int, default=1, help="whole-stage runs of the former and the new code, alternated (default 1)")
    ap.add_argument("--out", default=str(REPO / "results" / "benchmarks" / "gully_benchmark.md"))
    ap.add_argument("--stage-child", nargs=3, metavar=("DEM", "HEADS", "OUTDIR"), help=argparse.SUPPRESS)
    ap.add_argument("--sens-child", nargs=2, metavar=("DEM", "OUTDIR"), help=argparse.SUPPRESS)
    ap.add_argument("--val-child", nargs=2, metavar=("DEM", "OUTDIR"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.stage_child:
        run_stage(*args.stage_child, threads=args.threads)
        return
    if args.sens_child:
        run_sensitivity(*args.sens_child, threads=args.threads)
        return
    if args.val_child:
        run_validation(*args.val_child)
        return

    sys.path.insert(0, str(REPO / "src"))
    import scipy.ndimage as ndi

    from kitegully.io.raster import GridSpec, write_raster
    from kitegully.terrain.fill import priority_flood_fill
    from kitegully.terrain.smoothing import gaussian_smooth_fft

    cell = 0.2
    side = int(round(np.sqrt(args.cells)))
    lines = [f"# Gully stage benchmark ({side} x {side} = {side * side / 1e6:.1f} M cells at {cell} m, "
             f"{side * side * cell * cell / 1e6:.2f} km2; {args.threads} threads; {os.cpu_count()} CPUs on the machine)", ""]

    def say(msg: str) -> None:
        print(msg, flush=True)
        lines.append(msg)

    t0 = time.perf_counter()
    z, hx, hy, gparams = synthetic_catchment(side, cell)
    grid = GridSpec(500000.0, 4100000.0, cell, side, side, CRS)
    print(f"synthetic DEM made in {time.perf_counter() - t0:.1f} s", flush=True)

    with tempfile.TemporaryDirectory(prefix="gully_bench_") as tmp:
        tmp = Path(tmp)
        # 1. whole stage in a child process (its own peak memory)
        dem_tif = tmp / "dem.tif"
        write_raster(dem_tif, z, grid)
        heads = tmp / "heads.npy"
        np.save(heads, np.vstack([grid.x0 + hx, grid.y0 - hy]))
        (tmp / "out").mkdir()
        import geopandas as gpd

        from kitegully.io.vectors import write_vector

        write_vector(gpd.GeoDataFrame(geometry=centrelines(gparams, side, cell, grid.x0, grid.y0), crs=CRS),
                     tmp / "out" / "reference.gpkg")
        # a 1000 x 1000 corner with the same heads: a warm-up run of each revision before its timed
        # run, so that neither is timed compiling its numba kernels (a former revision's source is
        # a fresh copy, without numba's cache)
        small = tmp / "small"
        small.mkdir()
        cs = min(side, 1000)
        write_raster(small / "dem.tif", z[:cs, :cs], GridSpec(grid.x0, grid.y0, cell, cs, cs, CRS))
        shutil.copy(tmp / "out" / "reference.gpkg", small / "reference.gpkg")

        def whole_stage(src: str, out: Path, dem: Path = dem_tif) -> dict:
            """The three rules' work in child processes importing kitegully from ``src``: wall and CPU
            (user + system of the child, all its threads) times per rule."""
            env = dict(os.environ, KITEGULLY_BENCH_SRC=src)
            r = {}
            for key, extra in (("map", ["--stage-child", str(dem), str(heads), str(out)]),
                               ("sens", ["--sens-child", str(dem), str(out)]),
                               ("val", ["--val-child", str(dem), str(out)])):
                t0 = time.perf_counter()
                c0 = resource.getrusage(resource.RUSAGE_CHILDREN)
                p = subprocess.run([sys.executable, __file__, "--threads", str(args.threads), *extra],
                                   capture_output=True, text=True, env=env)
                c1 = resource.getrusage(resource.RUSAGE_CHILDREN)
                r[key + "_wall"] = time.perf_counter() - t0
                r[key + "_user"] = c1.ru_utime - c0.ru_utime
                r[key + "_sys"] = c1.ru_stime - c0.ru_stime
                r[key + "_cpu"] = r[key + "_user"] + r[key + "_sys"]
                if p.returncode != 0:
                    raise SystemExit(f"{key} run failed:\n{p.stderr[-3000:]}")
                r[key] = json.loads(p.stdout.strip().splitlines()[-1])
            r["total"] = r["map_wall"] + r["sens_wall"] + r["val_wall"]
            r["cpu"] = r["map_cpu"] + r["sens_cpu"] + r["val_cpu"]
            r["peak"] = max(r[k]["peak_gb"] for k in ("map", "sens", "val"))
            r["load"] = os.getloadavg()[0]
            return r

        def cpu_text(r: dict) -> str:
            return (f"CPU (user + sys) mapping {r['map_cpu']:.1f} ({r['map_user']:.1f} + {r['map_sys']:.1f}), sensitivity "
                    f"{r['sens_cpu']:.1f} ({r['sens_user']:.1f} + {r['sens_sys']:.1f}), validation {r['val_cpu']:.1f} "
                    f"({r['val_user']:.1f} + {r['val_sys']:.1f}), whole stage **{r['cpu']:.1f} s**")

        if args.against:
            # the former revision's src (its gully stage and fill are timed beside the new ones)
            fsrc = tmp / "former"
            fsrc.mkdir()
            arc = subprocess.run(["git", "-C", str(REPO), "archive", args.against, "src"], capture_output=True, check=True)
            subprocess.run(["tar", "-x", "-C", str(fsrc)], input=arc.stdout, check=True)
        if not args.fill_only:
            formers, news = [], []
            if args.against:
                (tmp / "out_former").mkdir()
                shutil.copy(tmp / "out" / "reference.gpkg", tmp / "out_former" / "reference.gpkg")
                whole_stage(str(fsrc / "src"), small, small / "dem.tif")  # warm-up
            whole_stage(str(REPO / "src"), small, small / "dem.tif")  # warm-up
            # the former code first, on the same DEM and reference, then the new; --rounds alternates them
            for _ in range(max(1, args.rounds)):
                if args.against:
                    formers.append(whole_stage(str(fsrc / "src"), tmp / "out_former"))
                news.append(whole_stage(str(REPO / "src"), tmp / "out"))
            new = news[-1]
            former = formers[-1] if formers else None
            info, vinfo = new["map"], new["val"]
            say("## Whole gully stage (rules gully_map, gully_sensitivity, gully_validate, one after the other)")
            say("")
            say(f"- mapping (read DEM -> gully map, network, polygons written): wall time {new['map_wall']:.1f} s, "
                f"peak memory {info['peak_gb']:.2f} GB")
            say("- steps (s): " + ", ".join(f"{k[:-2]} {v:.1f}" for k, v in info.items() if k.endswith("_s")))
            say(f"- {info['n_gullies']} gullies, traced network {info['network_length_m']:.0f} m, paths ending in a pit: {info['paths_in_pit']}")
            g = site_gully_config()
            say(f"- sensitivity table ({len(g['sensitivity']['sigmas_m'])} sigmas x {len(g['sensitivity']['depth_thresholds_m'])} "
                f"thresholds, depth at {g['sigma_m']:g} m reused, network scored at {g['validation']['tolerance_m']:g} m): "
                f"wall time {new['sens_wall']:.1f} s, peak memory {new['sens']['peak_gb']:.2f} GB")
            say(f"- network validation (score_network: footprint, reference filter, {len(vinfo['tolerances_m'])} tolerances "
                "x 2 reference sets; Fig. 9b map): "
                f"wall time {new['val_wall']:.1f} s (" + ", ".join(f"{k[:-2]} {v:.1f} s" for k, v in vinfo.items() if k.endswith("_s"))
                + "); good fit against all the constructed centrelines at "
                + "/".join(f"{t:g}" for t in vinfo["tolerances_m"]) + " m: "
                + " / ".join(f"{v:.1f} %" for v in vinfo["good_fit_percent"].values()))
            say(f"- **whole stage: {new['total']:.1f} s** (issue 21 target <= 90 s on 2 cores), peak memory of any rule "
                f"{new['peak']:.2f} GB (target < 8 GB); load average {new['load']:.1f} at its end on {os.cpu_count()} CPUs")
            say("- " + cpu_text(new))
            if former is not None:
                import pandas as pd
                import rasterio

                def read(path):
                    with rasterio.open(path) as src:
                        return src.read(1)

                def same_raster(name):
                    return np.array_equal(read(tmp / "out" / name), read(tmp / "out_former" / name), equal_nan=True)

                def float_raster(name):
                    """'identical', or the largest difference and how many cells differ (float rasters)."""
                    a, b = read(tmp / "out" / name).astype(np.float64), read(tmp / "out_former" / name).astype(np.float64)
                    if np.array_equal(a, b, equal_nan=True):
                        return "identical"
                    if not np.array_equal(np.isnan(a), np.isnan(b)):
                        return "DIFFERENT (nodata cells)"
                    d = np.abs(np.nan_to_num(a - b))
                    return f"equal within {d.max():.2e} m ({np.count_nonzero(d)} of {d.size} cells differ)"

                def same_npz(name):
                    a, b = np.load(tmp / "out" / name), np.load(tmp / "out_former" / name)
                    return sorted(a.files) == sorted(b.files) and all(np.array_equal(a[k], b[k]) for k in a.files)

                def table_text(t_new, t_old):
                    if t_new.equals(t_old):
                        return "identical"
                    if list(t_new.columns) != list(t_old.columns) or t_new.shape != t_old.shape:
                        return "DIFFERENT (shape)"
                    num = t_new.select_dtypes("number").columns
                    if not t_new.drop(columns=num).equals(t_old.drop(columns=num)):
                        return "DIFFERENT"
                    rel = (t_new[num] - t_old[num]).abs() / t_old[num].abs().where(t_old[num] != 0, 1.0)
                    worst = rel.max()
                    return ("equal within a relative " + f"{float(worst.max()):.1e}" + " (" +
                            ", ".join(f"{c} {v:.1e}" for c, v in worst.items() if v > 0) + ")")
                same_map = same_raster("gully_map.tif")
                same_depth = float_raster("depth.tif")
                sens_text = table_text(pd.read_csv(tmp / "out" / "sensitivity.csv"), pd.read_csv(tmp / "out_former" / "sensitivity.csv"))
                others = {"smoothed DEM": float_raster("smoothed.tif"),
                          "whole-patch map": "identical" if same_raster("gully_map_whole.tif") else "DIFFERENT",
                          "traced network cells": "identical" if same_npz("network.npz") else "DIFFERENT",
                          "validation good fit": "identical" if former["val"]["good_fit_percent"] == vinfo["good_fit_percent"] else "DIFFERENT"}
                say(f"- former code ({args.against}), same DEM, run just before: mapping {former['map_wall']:.1f} s, "
                    f"sensitivity {former['sens_wall']:.1f} s, validation {former['val_wall']:.1f} s, **whole stage "
                    f"{former['total']:.1f} s**, peak {former['peak']:.2f} GB (load average {former['load']:.1f} at its end); "
                    f"ratio former / new = **{former['total'] / new['total']:.2f}x**; gully map "
                    f"{'identical' if same_map else 'DIFFERENT'}, depth map {same_depth}, "
                    f"sensitivity table {sens_text}; "
                    + ", ".join(f"{k} {v}" for k, v in others.items())
                    + f"; network length {former['map']['network_length_m']:.0f} m vs {info['network_length_m']:.0f} m")
                say("- former code's " + cpu_text(former))
                for i, (f, n) in enumerate(zip(formers, news), 1):
                    say(f"- round {i} (former, then new): CPU former / new: mapping {f['map_cpu']:.1f} / {n['map_cpu']:.1f}, "
                        f"sensitivity {f['sens_cpu']:.1f} / {n['sens_cpu']:.1f}, validation {f['val_cpu']:.1f} / "
                        f"{n['val_cpu']:.1f}, whole stage {f['cpu']:.1f} / {n['cpu']:.1f} s = **{f['cpu'] / n['cpu']:.2f}x**; "
                        f"wall {f['total']:.1f} / {n['total']:.1f} s; peak {f['peak']:.2f} / {n['peak']:.2f} GB")
            say("")
        if args.stage_only:
            Path(args.out).parent.mkdir(parents=True, exist_ok=True)
            Path(args.out).write_text("\n".join(lines) + "\n", encoding="utf-8")
            print(f"written {args.out}")
            return

        # 2. smoothing: ours vs scipy.ndimage.gaussian_filter
        if not args.fill_only:
            sigma = 10.0 / cell
            say(f"## Gaussian smoothing, sigma = 10 m = {sigma:.0f} cells, kernel radius 4 sigma")
            say("")
            t0 = time.perf_counter()
            ours = gaussian_smooth_fft(z, sigma, 4.0, workers=args.threads)
            t_ours = time.perf_counter() - t0
            say(f"- kitegully gaussian_smooth_fft (FFT, normalised convolution + edge correction): {t_ours:.1f} s")
            if not args.skip_scipy:
                t0 = time.perf_counter()
                ref = ndi.gaussian_filter(z, sigma, truncate=4.0, mode="nearest")
                t_sp = time.perf_counter() - t0
                r = int(4 * sigma) + 1
                diff = float(np.max(np.abs(ours[r:-r, r:-r] - ref[r:-r, r:-r])))
                say(f"- scipy.ndimage.gaussian_filter (direct separable convolution, 1 thread): {t_sp:.1f} s")
                say(f"- ratio scipy / ours = {t_sp / t_ours:.2f}; max |difference| away from the edges = {diff:.2e} m")
                del ref
            del ours
            say("")

        # 3. depression filling on a tile: ours vs GRASS r.fill.dir vs pysheds
        tside = min(side, int(round(np.sqrt(args.compare_cells))))
        tile = np.ascontiguousarray(z[:tside, :tside], dtype=np.float64)
        say(f"## Depression filling on a {tside} x {tside} tile ({tside * tside / 1e6:.1f} M cells)")
        say("")
        priority_flood_fill(tile[:50, :50], 0.0)  # numba compile / cache load
        old_fill = None
        if args.against:
            import importlib.util

            ff = tmp / "former_fill.py"  # compiled here without numba's cache (a module without a package)
            ff.write_text((tmp / "former" / "src" / "kitegully" / "terrain" / "fill.py").read_text().replace("cache=True", "cache=False"))
            spec = importlib.util.spec_from_file_location("former_fill", ff)
            old_fill = importlib.util.module_from_spec(spec)
            spec.loader.exec_module(old_fill)
            old_fill.priority_flood_fill(tile[:50, :50], 0.0)
        # ours (and the former code's) alternated 3 times: medians
        t_new, t_old = [], []
        for _ in range(3):
            if old_fill is not None:
                t0 = time.perf_counter()
                fo, no = old_fill.priority_flood_fill(tile, 0.0)
                t_old.append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            f0, n0 = priority_flood_fill(tile, 0.0)
            t_new.append(time.perf_counter() - t0)
        t_f0 = float(np.median(t_new))
        if old_fill is not None:
            say(f"- former priority_flood_fill ({args.against}): {np.median(t_old):.2f} s; "
                f"ratio former / ours = {np.median(np.array(t_old) / np.array(t_new)):.2f}x (median of 3 paired runs); "
                f"{'identical' if np.array_equal(fo, f0, equal_nan=True) and no == n0 else 'DIFFERENT'} surface")
        t0 = time.perf_counter()
        priority_flood_fill(tile, 1e-4)
        t_fe = time.perf_counter() - t0
        say(f"- kitegully priority_flood_fill: {t_f0:.2f} s (eps = 0, median of 3), {t_fe:.2f} s (eps = 1e-4 m); {n0} cells raised")
        t0 = time.perf_counter()
        priority_flood_fill(z, 1e-4)
        say(f"- kitegully priority_flood_fill on the full {side * side / 1e6:.0f} M cells (eps = 1e-4 m): {time.perf_counter() - t0:.1f} s")
        from kitegully.terrain.flats import flow_directions

        full0, _ = priority_flood_fill(z, 0.0)
        flow_directions(full0[:50, :50])  # numba compile / cache load
        t0 = time.perf_counter()
        _dirs, n_flat, n_left = flow_directions(full0)
        say(f"- kitegully flow_directions with flat resolution on the full eps = 0 fill: {time.perf_counter() - t0:.1f} s; "
            f"{n_flat} flat cells routed, {n_left} left undrained")
        del full0, _dirs
        tile_tif = tmp / "tile.tif"
        write_raster(tile_tif, tile.astype(np.float64), GridSpec(grid.x0, grid.y0, cell, tside, tside, CRS))
        grass = None if args.skip_grass else ensure_grass()
        if grass:
            # GRASS 3 times, ours once right after each (the load moves): medians of each decide the ratio
            t_gs, fg = [], None
            for _ in range(args.grass_runs):
                g = grass_fill(grass, tile_tif, tmp)
                if not g:
                    break
                t_gs.append(g[0])
                fg = g[1]
                t0 = time.perf_counter()
                priority_flood_fill(tile, 0.0)
                t_new.append(time.perf_counter() - t0)
            if t_gs:
                t_g = float(np.median(t_gs))
                t_around = float(np.median(t_new))
                inner = (slice(1, -1), slice(1, -1))
                same = float(np.mean(np.abs(fg[inner] - f0[inner]) < 1e-6)) * 100
                say(f"- GRASS r.fill.dir: {t_g:.2f} s (median of {len(t_gs)}: " + " / ".join(f"{v:.2f}" for v in t_gs)
                    + f"; load average {os.getloadavg()[0]:.1f}); ours {t_around:.2f} s (median of the {len(t_new)} runs: "
                    f"the 3 above and one right after each GRASS run); ratio GRASS / ours = **{t_g / t_around:.1f}x**; "
                    f"cells equal to our minimal fill: {same:.2f} % (r.fill.dir is not the minimal fill; edge cells excluded)")
        elif args.skip_grass:
            say("- GRASS comparison skipped (--skip-grass)")
        py = None if args.skip_pysheds else ensure_pysheds(Path(tempfile.gettempdir()) / "kitegully-pysheds-venv")
        if py:
            np.save(tmp / "tile.npy", tile)
            child = tmp / "pysheds_child.py"
            child.write_text(PYSHEDS_CHILD)
            p = subprocess.run([str(py), str(child), str(tmp / "tile.npy"), str(tmp / "ps.npy")], capture_output=True, text=True)
            if p.returncode == 0:
                t_p = json.loads(p.stdout.strip().splitlines()[-1])["fill_s"]
                fp = np.load(tmp / "ps.npy")
                diff = float(np.nanmax(np.abs(fp - f0)))
                say(f"- pysheds {PYSHEDS_PIN.split('==')[1]} fill_depressions: {t_p:.2f} s; ratio pysheds / ours = {t_p / t_f0:.1f}; "
                    f"max |difference| to our eps = 0 fill = {diff:.2e} m")
            else:
                say(f"- pysheds run failed: {p.stderr.strip()[-300:]}")
        elif args.skip_pysheds:
            say("- pysheds comparison skipped (--skip-pysheds)")
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text("\n".join(lines) + "\n", encoding="utf-8")
    print(f"written {out}")


if __name__ == "__main__":
    main()
