"""Tiled orthophoto (issue 21) against the untiled one on a stored dense result: identity, time, memory.

Usage: ``python benchmarks/ortho_tiles.py FOLDER SITE_YAML [TILING_YAML] [--main SRC]``. FOLDER
holds ``model/``, ``transform.json``, ``sfm_work/images/`` and ``dsm.tif`` (a copy of one
epoch's georef and dense results). Each step runs in its own process (wall time and peak RSS):
the untiled ``orthophoto()`` (and, with ``--main``, the same call from another source tree, to
show untiled sites unchanged), then ``plan_orthophoto``, one ``render_ortho_tile`` per tile
and ``merge_ortho_tiles`` with the tiled site's config; writes ``FOLDER/ortho_tiles.csv``.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

STEP = r"""
import json, resource, sys, time
from pathlib import Path
import numpy as np
cfg = json.loads(sys.argv[1]); d = Path(cfg["folder"])
from kitegully.dense import DenseParams
from kitegully.dense.views import read_offset, views_from_reconstruction
from kitegully.io.raster import read_raster
import pycolmap
p = DenseParams.from_config(cfg["dense"])
views = views_from_reconstruction(pycolmap.Reconstruction(str(d / "model")), d / "sfm_work" / "images",
                                  read_offset(d / "transform.json"), where=str(d / "model"))
t0 = time.perf_counter()
if cfg["step"] == "untiled":
    from kitegully.dense.ortho import orthophoto
    dsm, grid = read_raster(d / "dsm.tif")
    oc = p.orthophoto
    img, og, src = orthophoto(views, dsm, grid, oc.upsample, oc.tile_cells, oc.overlap_m, oc.occlusion_tolerance_m, p.max_cached_images)
    np.savez(cfg["out"], image=img, source=src)
else:
    from kitegully.dense.ortho_tiles import merge_ortho_tiles, plan_orthophoto, render_ortho_tile
    from kitegully.terrain.tiling import TilingParams
    w = d / "tiled"
    if cfg["step"] == "plan":
        plan_orthophoto(views, d / "dsm.tif", p, w / "filled.tif", w / "plan.json")
    elif cfg["step"] == "merge":
        merge_ortho_tiles(sorted(map(str, w.glob("r*_c*.npz"))), d / "dsm.tif", w / "orthophoto.tif", w / "stats.json")
    else:
        render_ortho_tile(views, w / "filled.tif", w / "plan.json", p, TilingParams(**cfg["tiling"]), cfg["step"], w / (cfg["step"] + ".npz"))
print(json.dumps({"s": time.perf_counter() - t0, "rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""


def step(src: str, cfg: dict) -> dict:
    t0 = time.perf_counter()
    out = subprocess.run([sys.executable, "-c", STEP, json.dumps(cfg)], env={"PYTHONPATH": src, "PATH": "/usr/bin:/bin"},
                         capture_output=True, text=True)
    if out.returncode:
        raise RuntimeError(out.stderr[-3000:])
    r = json.loads(out.stdout.strip().splitlines()[-1])
    r["wall_s"] = time.perf_counter() - t0
    return r


def main(argv: list[str]) -> None:
    import numpy as np
    import pandas as pd
    import rasterio

    from kitegully.config import load_yaml
    from kitegully.terrain.tiling import TilingParams

    main_src = None
    if "--main" in argv:
        i = argv.index("--main")
        main_src = argv[i + 1]
        argv = argv[:i] + argv[i + 2:]
    folder, site = Path(argv[0]), load_yaml(argv[1])
    over = load_yaml(argv[2]) if len(argv) > 2 else {}
    here = str(Path(__file__).resolve().parents[1] / "src")
    dense_untiled = site["dense"]
    dense = json.loads(json.dumps(dense_untiled))
    dense.setdefault("orthophoto", {}).update((over.get("dense") or {}).get("orthophoto", {}))
    with rasterio.open(folder / "dsm.tif") as s:
        w_m, h_m = s.width * s.res[0], s.height * s.res[1]
    tiling = {"tile_m": float(over["tiling"]["tile_m"]), "width_m": w_m, "height_m": h_m}
    (folder / "tiled").mkdir(exist_ok=True)
    rows = []
    base = {"folder": str(folder), "tiling": tiling}
    rows.append({"step": "untiled (site config)", **step(here, {**base, "dense": dense_untiled, "step": "untiled", "out": str(folder / "untiled.npz")})})
    if main_src:
        rows.append({"step": "untiled, --main source", **step(main_src, {**base, "dense": dense_untiled, "step": "untiled", "out": str(folder / "untiled_main.npz")})})
    rows.append({"step": "untiled (tiled config)", **step(here, {**base, "dense": dense, "step": "untiled", "out": str(folder / "untiled_t.npz")})})
    rows.append({"step": "ortho_plan", **step(here, {**base, "dense": dense, "step": "plan"})})
    for name in TilingParams(**tiling).names():
        rows.append({"step": f"ortho_tile {name}", **step(here, {**base, "dense": dense, "step": name})})
    rows.append({"step": "ortho_merge", **step(here, {**base, "dense": dense, "step": "merge"})})
    df = pd.DataFrame(rows)
    tiled_sum = df[df.step.str.startswith("ortho_")][["s"]].sum().iloc[0]
    with rasterio.open(folder / "tiled" / "orthophoto.tif") as o:
        t_img, t_mask = o.read(), o.dataset_mask() > 0
    ref = np.load(folder / "untiled_t.npz")
    diff = np.abs(t_img.astype(int) - ref["image"].astype(int))
    res = {"max_abs_diff_dn": int(diff.max()), "differing_cells": int((diff > 0).any(axis=0).sum()),
           "mask_differs": int((t_mask != (ref["source"] >= 0)).sum()), "cells": int(t_mask.size),
           "tiled_steps_s": float(tiled_sum)}
    if main_src:
        a, b = np.load(folder / "untiled.npz"), np.load(folder / "untiled_main.npz")
        res["untiled_vs_main_differing_values"] = int((a["image"] != b["image"]).sum() + (a["source"] != b["source"]).sum())
    df.to_csv(folder / "ortho_tiles.csv", index=False)
    print(df.to_string(index=False))
    print(json.dumps(res, indent=1))


if __name__ == "__main__":
    main(sys.argv[1:])
