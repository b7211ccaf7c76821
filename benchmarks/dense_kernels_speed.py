"""Speed of the dense matcher's kernels and of one whole tile: new code vs the former one.

Renders the synthetic block of ``benchmarks/dense_benchmark.py`` (5 x 5 nadir views), takes
one tile of the default site's shape (256 + 2 x 32 cells) with the default site's matcher
settings, and times, alternating old and new in the same process (the machine is shared):

- ``sample_stack`` (former loop order: label innermost, vs the new: rows contiguous);
- the whole winner step (cost, SGM, argmin, parabola) on every pass's real NCC volume:
  former numpy code vs the compiled cost transpose and fused winner;
- the share of the sampling, NCC and winner kernels in one tile;
- ``match_tile`` as a whole with the former and the new winner step.

Reports medians and the max |difference| of the results. Writes
``benchmarks/out/dense_kernels_speed.md``.

Usage: PYTHONPATH=src .venv/bin/python benchmarks/dense_kernels_speed.py [--threads 2] [--repeats 5]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numba
import numpy as np
import yaml
from numba import njit, prange

from kitegully.dense.kernels import _bilinear, _project

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))


@njit(parallel=True)
def sample_stack_former(imgs, Rs, Cs, Ps, levels, xs, ys, base, dz, out):
    """The former loop order of ``kitegully.dense.kernels.sample_stack`` (k innermost)."""
    K, V, H, W = out.shape
    for i in prange(H):
        for v in range(V):
            img = imgs[v]
            sc = 1.0 / (2.0 ** levels[v])
            R = Rs[v]
            C = Cs[v]
            p = Ps[v]
            for j in range(W):
                for k in range(K):
                    z = base[i, j] + k * dz
                    u, w, d = _project(R, C, p, xs[j], ys[i], z)
                    if d <= 0.0 or not np.isfinite(z):
                        out[k, v, i, j] = np.nan
                    else:
                        out[k, v, i, j] = _bilinear(img, (u + 0.5) * sc - 0.5, (w + 0.5) * sc - 0.5)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--side", type=int, default=320, help="tile side in cells (core + 2 overlaps)")
    args = ap.parse_args()
    numba.set_num_threads(args.threads)

    import dense_synthetic as ds
    from kitegully.dense import matching as m
    from kitegully.dense.kernels import multiview_ncc_stack, sample_stack
    from kitegully.dense.surface import tile_z_range
    from kitegully.dense.views import PyramidCache
    from kitegully.seeds import rng_for

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

    # record every pass's NCC volume and time the kernels inside one tile
    passes: list[tuple[np.ndarray, int]] = []
    spent = {"sample_stack": 0.0, "multiview_ncc_stack": 0.0, "winner": 0.0}

    def timed(name, fn):
        def wrap(*a, **k):
            t = time.perf_counter()
            r = fn(*a, **k)
            spent[name] += time.perf_counter() - t
            return r
        return wrap

    orig = (m.sample_stack, m.multiview_ncc_stack, m._sgm_winner)
    new_winner = m._sgm_winner

    sampled = []

    def record_sample(*a):
        sampled.append(a)
        return sample_stack(*a)

    def record(score, K, params):
        passes.append((score.copy(), K))
        return new_winner(score, K, params)

    m.match_tile(views, cache, xs, ys, cell, zr, p)  # JIT warm-up
    m._sgm_winner_reference(np.zeros((3, 8, 8), np.float32), 3, p)
    m.sample_stack = timed("sample_stack", record_sample)
    m.multiview_ncc_stack = timed("multiview_ncc_stack", multiview_ncc_stack)
    m._sgm_winner = timed("winner", record)
    t = time.perf_counter()
    m.match_tile(views, cache, xs, ys, cell, zr, p)
    total_one = time.perf_counter() - t
    m.sample_stack, m.multiview_ncc_stack, m._sgm_winner = orig

    def med_pair(f_old, f_new):
        old, new = [], []
        for _ in range(args.repeats):
            for f, acc in ((f_old, old), (f_new, new)):
                t = time.perf_counter()
                f()
                acc.append(time.perf_counter() - t)
        return statistics.median(old), statistics.median(new), [o / n for o, n in zip(old, new)]

    rows = []
    outs = [(np.empty_like(a[-1]), np.empty_like(a[-1])) for a in sampled]
    o, n_, r = med_pair(lambda: [sample_stack_former(*a[:-1], oo[0]) for a, oo in zip(sampled, outs)],
                        lambda: [sample_stack(*a[:-1], oo[1]) for a, oo in zip(sampled, outs)])
    same = all(np.array_equal(a, b, equal_nan=True) for a, b in outs)
    rows.append(("sample_stack (all passes)", o, n_, statistics.median(r), "identical" if same else "DIFFERENT"))
    o, n_, r = med_pair(lambda: [m._sgm_winner_reference(s, K, p) for s, K in passes],
                        lambda: [m._sgm_winner(s, K, p) for s, K in passes])
    same = all(np.array_equal(a[0], b[0]) and np.array_equal(np.asarray(a[1], np.float64), np.asarray(b[1], np.float64))
               for a, b in ((m._sgm_winner_reference(s, K, p), m._sgm_winner(s, K, p)) for s, K in passes))
    rows.append(("winner step: cost + SGM (serial, unchanged) + argmin + parabola (all passes)", o, n_, statistics.median(r),
                 "identical" if same else "DIFFERENT"))

    # whole tile: former winner step and sampling order vs new
    def tile(ref: bool):
        m._sgm_winner = m._sgm_winner_reference if ref else new_winner
        m.sample_stack = sample_stack_former if ref else sample_stack
        try:
            return m.match_tile(views, cache, xs, ys, cell, zr, p)
        finally:
            m._sgm_winner = new_winner
            m.sample_stack = sample_stack
    res = {}
    o, n_, r = med_pair(lambda: res.__setitem__("old", tile(True)), lambda: res.__setitem__("new", tile(False)))
    zo, zn = res["old"].z, res["new"].z
    same = np.array_equal(zo, zn, equal_nan=True) and np.array_equal(res["old"].ncc, res["new"].ncc, equal_nan=True)
    dz = float(np.nanmax(np.abs(zo.astype(np.float64) - zn))) if np.isfinite(zo).any() else 0.0
    rows.append((f"match_tile {side}x{side} cells", o, n_, statistics.median(r),
                 "identical" if same else f"max |dz| {dz:.2e} m"))

    lines = [
        "# Dense matcher kernels: former vs new code",
        "",
        f"One {side}x{side}-cell tile (default site's tile 256 + 2x32 overlap and matcher settings: "
        f"{p.levels} levels, {p.final_passes} final passes, {p.sgm_directions} SGM directions) of the synthetic "
        f"5x5-view block, {args.threads} numba threads, {args.repeats} alternating repeats in one process, medians "
        "(shared machine: absolute times are noisy, the ratios are the result).",
        "",
        f"Share of one tile ({total_one:.2f} s with the new code, {len(passes)} passes): "
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
