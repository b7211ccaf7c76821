"""Dense matching with and without the view cap (``dense.matching.max_views``, issue 21), in one run.

Matches one window of a site's DSM grid (whole matching blocks, so the blocks, their halos
and tie-point elevation ranges are those of the site's dense run) with each cap of
``--caps`` (``none`` = every image whose frame meets a block, the former behaviour),
alternating the variants ABBA over ``--repeats`` so that load drift on the shared machine
cancels in the ratios. The inputs are read only: the georeferenced model, its transform,
the SfM work images and the twin's site.json under ``--results`` (as the dense_tile rule
builds its ViewSet: :func:`kitegully.dense.tiles.load_views_and_grid`).

Reports per variant: images visible and kept per block, matching time, cells/s and the
speed ratio to the first variant, valid cells and coverage of the cells seen by >= 2
images; the elevation difference to the first variant on cells valid in both (median, NMAD,
p95 of |d|, share of identical cells) and, per block, whether a block seen by no more
images than the cap is identical bit for bit. For evaluation only, where the twin's truth
exists (``twin/truth/dsm.tif``, ``twin/observed/checkpoints.csv``): the error of each
variant against the true DSM (all valid cells) and at the checkpoints in the window. The
DSM is the tile jobs' raw DSM (before the datum check of dense_merge, which shifts every
variant alike).

Writes ``--out`` (.md) and the same tables as .csv next to it.

Usage (full-size Kamech, one 512 x 512-cell window of tile r002_c002)::

    PYTHONPATH=src .venv/bin/python benchmarks/dense_view_cap.py --site config/sites/kamech_full.yaml \\
        --results results/kamech_full --rows 5120:5632 --cols 4096:4608 --caps none,20 --repeats 2

Default twin, whole grid: ``--site config/sites/kamech_twin.yaml --results results/kamech_twin``.
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import replace
from pathlib import Path

import numba
import numpy as np
import pandas as pd
import yaml

from kitegully.dense import DenseParams
from kitegully.dense.matching import visible_views
from kitegully.dense.surface import dense_surface, tile_z_range
from kitegully.dense.tiles import load_views_and_grid, matching_block
from kitegully.dense.view_selection import select_views
from kitegully.evaluate.dem import checkpoint_errors, error_stats, read_checkpoints, resample_to
from kitegully.dense.views import PyramidCache
from kitegully.io.raster import GridSpec

REPO = Path(__file__).resolve().parents[1]


def parse_variants(text: str) -> list[tuple[int | None, int | None]]:
    """``cap[@cache]`` items: max_views (``none`` = no cap) and optionally max_cached_images."""
    out = []
    for item in text.split(","):
        cap, _, cache = item.strip().partition("@")
        out.append((None if cap.lower() in ("none", "null") else int(cap), int(cache) if cache else None))
    return out


def cap_name(cap: int | None, cache: int | None = None) -> str:
    return ("uncapped" if cap is None else f"max_views={cap}") + (f", cache {cache}" if cache else "")


LOADS = [0]
_base = PyramidCache._base


def _counted_base(self, i):
    LOADS[0] += 1
    return _base(self, i)


PyramidCache._base = _counted_base  # counts image reads (cache misses) per run


def block_views(views, sub: GridSpec, params: DenseParams, caps) -> tuple[pd.DataFrame, set[int]]:
    """Images visible and kept for every matching block of ``sub`` (as dense_surface cuts it),
    and the set of all images visible from any block."""
    T, O = matching_block(params)
    local = sub.shifted(-views.offset[0], -views.offset[1])
    xs_all, ys_all = local.cell_centres(-O, -O, sub.height + T + 2 * O, sub.width + T + 2 * O)
    rows, seen = [], set()
    for r0 in range(0, sub.height, T):
        for c0 in range(0, sub.width, T):
            xs, ys = xs_all[c0:c0 + T + 2 * O], ys_all[r0:r0 + T + 2 * O]
            box = (xs[0] - sub.cell / 2, ys[-1] - sub.cell / 2, xs[-1] + sub.cell / 2, ys[0] + sub.cell / 2)
            zr = tile_z_range(views, (xs[0], ys[-1], xs[-1], ys[0]), params.matching.z_margin_m)
            idx = visible_views(views, (box[0], box[2]), (box[1], box[3]), zr)
            seen.update(idx)
            row = {"r0": r0, "c0": c0, "visible": len(idx)}
            for cap in caps:
                row[f"kept_{cap_name(cap)}"] = len(select_views(views, idx, box, 0.5 * (zr[0] + zr[1]), sub.cell, cap))
            rows.append(row)
    return pd.DataFrame(rows), seen


def read_truth(path: Path, sub: GridSpec) -> np.ndarray | None:
    """The true raster on ``sub`` (a window read, bilinear at the cell centres), or None."""
    if not path.exists():
        return None
    import rasterio
    from rasterio.windows import from_bounds

    with rasterio.open(path) as src:
        xmin, ymin, xmax, ymax = sub.bounds
        m = 2 * sub.cell
        win = from_bounds(xmin - m, ymin - m, xmax + m, ymax + m, src.transform).round_offsets().round_lengths()
        z = src.read(1, window=win, boundless=True, fill_value=np.nan).astype(np.float64)
        tg = GridSpec.from_transform(src.window_transform(win), z.shape[1], z.shape[0], sub.crs)
        if src.nodata is not None and np.isfinite(src.nodata):
            z[z == src.nodata] = np.nan
    return resample_to(z, tg, sub)


def abs_p95(d: np.ndarray) -> float:
    return float(np.percentile(np.abs(d), 95)) if d.size else float("nan")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--site", required=True, help="site config (its dense section)")
    ap.add_argument("--results", required=True, help="the site's results folder (read only)")
    ap.add_argument("--rows", default=None, help="DSM rows a:b of the window (default: all); a multiple of dense.tile_cells")
    ap.add_argument("--cols", default=None, help="DSM columns a:b of the window (default: all)")
    ap.add_argument("--caps", default="none,20", help="comma-separated variants max_views[@max_cached_images]; none = no "
                    "cap; the first is the reference; without @ the site's max_cached_images")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=1, help="ABBA repeats of the timed runs")
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "out" / "dense_view_cap.md"))
    args = ap.parse_args()

    numba.set_num_threads(max(1, min(args.threads, numba.config.NUMBA_NUM_THREADS)))
    res = Path(args.results)
    cfg = yaml.safe_load(Path(args.site).read_text(encoding="utf-8"))
    params = DenseParams.from_config(cfg["dense"])
    site_json = res / "twin" / "site.json"
    views, cell, params, grid = load_views_and_grid(res / "georef" / "model", res / "georef" / "transform.json",
                                                    res / "sfm" / "work" / "images", cfg["site"]["crs"], params,
                                                    site_json if site_json.exists() else None)
    T, O = matching_block(params)
    r0, r1 = (int(v) for v in args.rows.split(":")) if args.rows else (0, grid.height)
    c0, c1 = (int(v) for v in args.cols.split(":")) if args.cols else (0, grid.width)
    if r0 % T or c0 % T:
        raise SystemExit(f"window origin ({r0}, {c0}) must be a multiple of dense.tile_cells ({T})")
    r1, c1 = min(r1, grid.height), min(c1, grid.width)
    sub = grid.window(r0, c0, r1 - r0, c1 - c0)
    variants = parse_variants(args.caps)
    caps = [v[0] for v in variants]
    names = [cap_name(*v) for v in variants]
    print(f"{len(views.images)} images; window rows {r0}:{r1}, cols {c0}:{c1} ({sub.width * sub.height} cells, "
          f"{-(-sub.height // T) * -(-sub.width // T)} blocks of {T} + halo {O})", flush=True)

    blocks, used = block_views(views, sub, params, caps)
    print(blocks.describe().loc[["min", "50%", "max"]].to_string(), flush=True)

    # warm-up outside the timing: compiled kernels loaded, image files in the page cache
    for i in sorted(used):
        Path(views.images[i].path).read_bytes()
    dense_surface(views, sub.window(0, 0, min(T, sub.height), min(T, sub.width)), params.matching, T, O,
                  params.max_cached_images)

    order = []
    for rep in range(args.repeats):
        order += list(range(len(caps))) if rep % 2 == 0 else list(range(len(caps)))[::-1]
    seconds = {n: [] for n in names}
    loads = {}
    results = {}
    for k in order:
        mp = replace(params.matching, max_views=caps[k])
        LOADS[0] = 0
        t0 = time.perf_counter()
        r = dense_surface(views, sub, mp, T, O, variants[k][1] or params.max_cached_images)
        seconds[names[k]].append(time.perf_counter() - t0)
        loads[names[k]] = LOADS[0]
        results[names[k]] = r
        print(f"{names[k]}: {seconds[names[k]][-1]:.1f} s, {LOADS[0]} image reads", flush=True)

    truth = read_truth(res / "twin" / "truth" / "dsm.tif", sub)
    cps = None
    cp_path = res / "twin" / "observed" / "checkpoints.csv"
    if cp_path.exists():
        cps = read_checkpoints(cp_path)
        xmin, ymin, xmax, ymax = sub.bounds
        cps = cps[(cps.x > xmin) & (cps.x < xmax) & (cps.y > ymin) & (cps.y < ymax)]
    ref_name = names[0]
    ref = results[ref_name]
    cells = sub.width * sub.height
    t_ref = float(np.median(seconds[ref_name]))
    rows = []
    for n in names:
        r = results[n]
        t = float(np.median(seconds[n]))
        both = np.isfinite(r.dsm) & np.isfinite(ref.dsm)
        d = (r.dsm - ref.dsm)[both].astype(np.float64)
        kept = blocks[f"kept_{cap_name(caps[names.index(n)])}"]
        row = {"variant": n, "views_per_block_median": float(kept.median()), "views_per_block_max": int(kept.max()),
               "image_reads": loads[n],
               "matching_s": t, "cells_per_s": cells / t, "speed_ratio": t_ref / t,
               "valid_pct": 100 * float(np.isfinite(r.dsm).mean()), "coverage_of_seen_pct": 100 * r.coverage(),
               "diff_median_m": float(np.median(d)) if d.size else np.nan,
               "diff_nmad_m": float(1.4826 * np.median(np.abs(d - np.median(d)))) if d.size else np.nan,
               "diff_abs_p95_m": abs_p95(d), "identical_pct": 100 * float((d == 0).mean()) if d.size else np.nan}
        if truth is not None:
            s = error_stats(r.dsm.astype(np.float64) - truth)
            row.update({"truth_dsm_median_m": s["median"], "truth_dsm_nmad_m": s["nmad"],
                        "truth_dsm_abs_p95_m": abs_p95((r.dsm.astype(np.float64) - truth)[np.isfinite(r.dsm) & np.isfinite(truth)]),
                        "truth_dsm_rmse_m": s["rmse"], "truth_dsm_n": s["n"]})
        if cps is not None and len(cps):
            s = error_stats(checkpoint_errors(r.dsm, sub, cps)["error_m"].to_numpy())
            row.update({"checkpoint_mean_m": s["mean"], "checkpoint_sd_m": s["sd"], "checkpoint_n": s["n"]})
        rows.append(row)
    table = pd.DataFrame(rows)
    # per block: are blocks seen by no more images than the cap identical?
    same = []
    for _, b in blocks.iterrows():
        sl = (slice(int(b.r0), int(b.r0) + T), slice(int(b.c0), int(b.c0) + T))
        e = {"r0": int(b.r0), "c0": int(b.c0), "visible": int(b.visible)}
        for n in names[1:]:
            a, z = results[n].dsm[sl], ref.dsm[sl]
            e[f"identical_{n}"] = bool(np.array_equal(a, z, equal_nan=True))
        same.append(e)
    same = pd.DataFrame(same)
    lines = [f"# Dense matching with and without the view cap ({Path(args.site).stem})", "",
             f"Window rows {r0}:{r1}, cols {c0}:{c1} of the {grid.width} x {grid.height}-cell DSM grid ({cells} cells, "
             f"{len(blocks)} blocks of {T} cells + {O}-cell halo); {len(views.images)} images; {args.threads} threads; "
             f"image cache {params.max_cached_images} pyramids unless stated; "
             f"runs {' '.join(names[k] for k in order)} (times: median of the runs); machine shared, so read the ratios.",
             "", table.to_markdown(index=False, floatfmt=".4g"), ""]
    for n, cap in zip(names[1:], caps[1:]):
        if cap is None:
            lines.append(f"- {n}: identical to {ref_name} in {int(same[f'identical_{n}'].sum())} of {len(same)} blocks.")
            continue
        under = same[same.visible <= cap]
        over = same[same.visible > cap]
        lines.append(f"- {n}: {int(under[f'identical_{n}'].sum())} of {len(under)} blocks seen by <= {cap} images identical "
                     f"bit for bit; {len(over)} blocks seen by more (changed: {int((~over[f'identical_{n}']).sum())}).")
    lines += ["", "Images visible and kept per block:", "", blocks.to_markdown(index=False), ""]
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text("\n".join(lines), encoding="utf-8")
    table.to_csv(out.with_suffix(".csv"), index=False)
    blocks.merge(same, on=["r0", "c0", "visible"]).to_csv(out.with_name(out.stem + "_blocks.csv"), index=False)
    print("\n".join(lines[:6 + len(caps)]))
    print(json.dumps({"out": str(out)}))


if __name__ == "__main__":
    main()
