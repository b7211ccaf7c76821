"""Speed of the dense matcher's kernels and of one whole tile: new code vs a former revision.

Renders the synthetic block of ``benchmarks/dense_benchmark.py`` (5 x 5 nadir views), takes
one tile of the default site's shape (256 + 2 x 32 cells) with the default site's matcher
settings, and times, alternating former and new in the same process (the machine is shared,
so only ratios taken this way mean something):

- ``sample_stack`` (resampling of the image stack) on every pass's real inputs;
- ``multiview_ncc_stack`` (multi-view NCC) on every pass's real stack;
- the share of the sampling, NCC and SGM + winner steps in one tile;
- ``match_tile`` as a whole with the former and the new kernels.

The former kernels are not copied here: ``src/kitegully/dense/kernels.py`` is read from the
git revision ``--against`` (default: the last commit before issue 21's kernel rewrite) and
compiled in this process. Reports medians, the median of the paired ratios and whether the
results are identical (``array_equal``, NaN = NaN). Writes ``benchmarks/out/dense_kernels_speed.md``.

Usage: PYTHONPATH=src .venv/bin/python benchmarks/dense_kernels_speed.py [--threads 2] [--repeats 5] [--against REV]
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numba
import numpy as np
import yaml

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))
# main at the end of session 5: the per-cell NCC loop and the full projection per candidate
FORMER = "3974773"


def former_kernels(rev: str, tmp: Path):
    """The module ``kitegully.dense.kernels`` as it was at git revision ``rev``."""
    src = subprocess.run(["git", "-C", str(REPO), "show", f"{rev}:src/kitegully/dense/kernels.py"],
                         capture_output=True, text=True, check=True).stdout
    path = tmp / "former_kernels.py"
    path.write_text(src.replace("cache=True", "cache=False"), encoding="utf-8")
    spec = importlib.util.spec_from_file_location("former_kernels", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--side", type=int, default=320, help="tile side in cells (core + 2 overlaps)")
    ap.add_argument("--against", default=FORMER, help="git revision of the former kernels")
    args = ap.parse_args()
    numba.set_num_threads(args.threads)

    import dense_synthetic as ds
    from kitegully.dense import matching as m
    from kitegully.dense.kernels import multiview_ncc_stack, sample_stack
    from kitegully.dense.surface import tile_z_range
    from kitegully.dense.views import PyramidCache
    from kitegully.seeds import rng_for

    tmp = Path(tempfile.mkdtemp(prefix="dense_kernels_"))
    old = former_kernels(args.against, tmp)

    surface = ds.slope(gx=0.2, gy=-0.1)
    views, imgs, _ = ds.block(surface, rng_for(2018, "benchmark", "dense"), extent=12.0, height_m=40.0, f=800.0,
                              width=640, height=480, spacing=(8.0, 6.0), grid=(5, 5))
    cfg = yaml.safe_load(open(REPO / "config/sites/kamech_twin.yaml", encoding="utf-8"))["dense"]
    p = m.MatchParams.from_config(cfg["matching"])
    cell = 0.1
    side = args.side
    xs = (np.arange(side) - side / 2 + 0.5) * cell
    ys = (side / 2 - 0.5 - np.arange(side)) * cell
    cache = PyramidCache(views, 32, imgs)
    zr = tile_z_range(views, (xs[0], ys[-1], xs[-1], ys[0]), p.z_margin_m)

    spent = {"sample_stack": 0.0, "multiview_ncc_stack": 0.0, "SGM + winner": 0.0}
    sampled, nccin = [], []

    def timed(name, fn, keep=None):
        def wrap(*a, **k):
            if keep is not None:
                keep.append(a)
            t = time.perf_counter()
            r = fn(*a, **k)
            spent[name] += time.perf_counter() - t
            return r
        return wrap

    def use(sample, ncc):
        m.sample_stack, m.multiview_ncc_stack = sample, ncc

    # JIT warm-up of both versions
    use(old.sample_stack, old.multiview_ncc_stack)
    m.match_tile(views, cache, xs, ys, cell, zr, p)
    use(sample_stack, multiview_ncc_stack)
    m.match_tile(views, cache, xs, ys, cell, zr, p)
    winner = m._sgm_winner
    use(timed("sample_stack", sample_stack, sampled), timed("multiview_ncc_stack", multiview_ncc_stack, nccin))
    m._sgm_winner = timed("SGM + winner", winner)
    t = time.perf_counter()
    m.match_tile(views, cache, xs, ys, cell, zr, p)
    total_one = time.perf_counter() - t
    m._sgm_winner = winner
    use(sample_stack, multiview_ncc_stack)
    nccin = [tuple(x.copy() if isinstance(x, np.ndarray) else x for x in a) for a in nccin]

    def med_pair(f_old, f_new):
        o, n = [], []
        for _ in range(args.repeats):
            for f, acc in ((f_old, o), (f_new, n)):
                t = time.perf_counter()
                f()
                acc.append(time.perf_counter() - t)
        return statistics.median(o), statistics.median(n), statistics.median([a / b for a, b in zip(o, n)])

    def same(a, b):
        return all(np.array_equal(x, y, equal_nan=True) for x, y in zip(a, b))

    rows = []
    outs = [(np.empty_like(a[-1]), np.empty_like(a[-1])) for a in sampled]
    o, n_, r = med_pair(lambda: [old.sample_stack(*a[:-1], oo[0]) for a, oo in zip(sampled, outs)],
                        lambda: [sample_stack(*a[:-1], oo[1]) for a, oo in zip(sampled, outs)])
    rows.append(("sample_stack (all passes)", o, n_, r,
                 "identical" if same(*zip(*outs)) else "DIFFERENT"))
    outs = [tuple((np.empty_like(a[3]), np.empty_like(a[4])) for _ in range(2)) for a in nccin]
    o, n_, r = med_pair(lambda: [old.multiview_ncc_stack(*a[:3], *oo[0]) for a, oo in zip(nccin, outs)],
                        lambda: [multiview_ncc_stack(*a[:3], *oo[1]) for a, oo in zip(nccin, outs)])
    ok = all(same(a, b) for a, b in outs)
    rows.append(("multiview_ncc_stack (all passes)", o, n_, r, "identical" if ok else "DIFFERENT"))

    res = {}

    def tile(former: bool):
        use(*((old.sample_stack, old.multiview_ncc_stack) if former else (sample_stack, multiview_ncc_stack)))
        try:
            return m.match_tile(views, cache, xs, ys, cell, zr, p)
        finally:
            use(sample_stack, multiview_ncc_stack)
    o, n_, r = med_pair(lambda: res.__setitem__("old", tile(True)), lambda: res.__setitem__("new", tile(False)))
    a, b = res["old"], res["new"]
    ok = same((a.z, a.ncc, a.nviews), (b.z, b.ncc, b.nviews))
    rows.append((f"match_tile {side}x{side} cells", o, n_, r, "identical (z, NCC, view counts)" if ok else "DIFFERENT"))

    load = os.getloadavg()
    lines = [
        f"# Dense matcher kernels: former ({args.against}) vs new code",
        "",
        f"One {side}x{side}-cell tile (default site's tile 256 + 2x32 overlap and matcher settings: "
        f"{p.levels} levels, {p.final_passes} final passes, {p.sgm_directions} SGM directions) of the synthetic "
        f"5x5-view block, {args.threads} numba threads, {args.repeats} alternating repeats in one process, medians "
        f"(shared machine, load average {load[0]:.1f} / {load[1]:.1f} / {load[2]:.1f} at the end on "
        f"{os.cpu_count()} CPUs: absolute times are noisy, the ratios are the result).",
        "",
        f"Share of one tile with the new code ({total_one:.2f} s, {side * side / total_one:,.0f} cells/s): "
        + ", ".join(f"{k} {v:.2f} s ({100 * v / total_one:.0f} %)" for k, v in spent.items())
        + f", rest {total_one - sum(spent.values()):.2f} s.",
        "",
        "| step | former (s) | new (s) | speed-up (median of paired ratios) | results |",
        "|---|---:|---:|---:|---|",
    ]
    for name, o, n_, r, s in rows:
        lines.append(f"| {name} | {o:.3f} | {n_:.3f} | {r:.2f}x | {s} |")
    out = REPO / "benchmarks" / "out" / "dense_kernels_speed.md"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text("\n".join(lines) + "\n", encoding="utf-8")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
