"""Which automatic gully heads are false, and what they cost (issue 15; evaluation only).

Maps each ensemble twin's existing photogrammetric DSM with ``gully.heads: automatic`` (the
member's merged settings, current code) and describes every detected head: its distance to
the nearest true centreline (a head farther than the 5 m tolerance is *false*), the true land
cover under it (twin truth), its distance to the DSM's nodata/edge, its head-scale incision
depth in units of the detector's threshold, how far its path runs in channel cells, its own
path length (to the first confluence with an earlier path or the outlet) and how much of that
lies farther than the tolerance from the reference (its false-positive length). Then sums
false heads and false-positive length by land cover and by incision depth.

Writes under ``--out`` (default ``results/ensemble_auto_fp``): ``auto_heads_<member>.csv``
and ``auto_fp_summary.csv/.md``.

    PYTHONPATH=src .venv/bin/python benchmarks/gully_auto_fp_analysis.py --results /work/wt/ensrun/results
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import shapely
import yaml
from scipy.spatial import cKDTree

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "src"))
sys.path.insert(0, str(REPO / "benchmarks"))

from gully_ensemble_misses import member_cfg  # noqa: E402
from twin_ensemble import BASE, members  # noqa: E402

from kitegully.evaluate.dem import read_checkpoints  # noqa: E402
from kitegully.gully.heads import HeadDetectionParams  # noqa: E402
from kitegully.gully.relief import dsm_noise_at_checkpoints, head_scale_relief  # noqa: E402
from kitegully.gully.params import GullyParams  # noqa: E402
from kitegully.gully.pipeline import map_gullies  # noqa: E402
from kitegully.gully.surface import tracing_surface  # noqa: E402
from kitegully.io.raster import read_raster  # noqa: E402
from kitegully.io.tables import write_table  # noqa: E402
from kitegully.io.vectors import read_vector  # noqa: E402
from kitegully.terrain.fill import priority_flood_fill  # noqa: E402
from kitegully.terrain.flats import flow_directions  # noqa: E402
from kitegully.terrain.flow import trace_paths  # noqa: E402

log = logging.getLogger("gully_auto_fp_analysis")


def analyse_member(cfg: dict, site: Path) -> pd.DataFrame:
    """One row per automatic head of the member's DSM."""
    g = cfg["gully"]
    crs = cfg["site"]["crs"]
    tol = float(g["validation"]["tolerance_m"])
    dem, grid = read_raster(site / "dense/dsm.tif")
    dem = np.asarray(dem, dtype=np.float32)
    twin = site / "twin"
    sz = dsm_noise_at_checkpoints(dem, grid, read_checkpoints(twin / "observed/checkpoints.csv"))
    ip = HeadDetectionParams.from_config(g["automatic_heads"], sz)
    params = GullyParams.from_config(g)
    ortho = None
    if params.crowns.enabled:  # gully.crowns: the orthophoto on the DSM grid
        from kitegully.gully.inputs import read_orthophoto_on_grid

        ortho = read_orthophoto_on_grid(site / "dense/orthophoto.tif", grid)
    res = map_gullies(dem, grid, np.zeros(0), np.zeros(0), params, workers=1, auto_heads=ip, ortho=ortho)
    heads = res.auto_heads
    xy = grid.flat_xy(heads)
    cl = read_vector(twin / "truth/gully_centrelines.gpkg", crs=crs)
    verts = np.concatenate([shapely.get_coordinates(geom) for geom in cl.geometry])
    d_true = cKDTree(verts).query(xy, k=1)[0] if len(xy) else np.zeros(0)
    lc, lgrid = read_raster(twin / "truth/landcover.tif")
    names = pd.read_csv(twin / "truth/landcover_classes.csv").set_index("code")["name"].to_dict()
    r, c = lgrid.rowcol(xy[:, 0], xy[:, 1])
    r = np.clip(np.rint(r).astype(int), 0, lc.shape[0] - 1)
    c = np.clip(np.rint(c).astype(int), 0, lc.shape[1] - 1)
    cover = [names.get(int(v), str(v)) for v in lc[r, c]]
    # distance to nodata / DSM edge
    src = np.pad(np.where(np.isfinite(dem), 1, 0).astype(np.uint8), 1)
    dist_nd = cv2.distanceTransform(src, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)[1:-1, 1:-1] * grid.cell
    hr, hc = np.divmod(heads, grid.width)
    relief, rough = head_scale_relief(dem, grid.cell, ip, 1)
    thr = ip.relief_k * max(ip.dsm_sigma_z_m, rough)
    # each head's own path (traced in the same order as the pipeline)
    _zh, zt, _n = tracing_surface(dem, grid, params, 1, ip, hidden=res.crowns)
    filled, _r = priority_flood_fill(zt, 0.0)
    dirs = flow_directions(filled)[0]
    cells, _down, starts, ends = trace_paths(filled, heads, dirs)
    ref = read_vector(twin / "observed/field_network.gpkg", crs=crs)
    ref_u = shapely.union_all(list(ref.geometry))
    gully = res.gully.ravel()
    rows = []
    for k in range(len(heads)):
        pc = cells[starts[k]:starts[k + 1]]
        pxy = grid.flat_xy(pc)
        step = np.hypot(*np.diff(pxy, axis=0).T).sum() / max(len(pc) - 1, 1) if len(pc) > 1 else grid.cell
        far = shapely.distance(shapely.points(pxy), ref_u) > tol if len(pc) else np.zeros(0, bool)
        in_map = gully[pc] if len(pc) else np.zeros(0, bool)
        first_in = int(np.argmax(in_map)) if in_map.any() else len(pc)
        rows.append({"x": xy[k, 0], "y": xy[k, 1], "to_true_centreline_m": d_true[k], "false": d_true[k] > tol,
                     "landcover": cover[k], "to_nodata_m": dist_nd[hr[k], hc[k]],
                     "relief_over_threshold": float(relief[hr[k], hc[k]] / thr),
                     "path_m": len(pc) * step, "path_far_m": float(far.sum() * step),
                     "path_far_mapped_m": float((far & gully[pc]).sum() * step), "end": int(ends[k]),
                     # the pipeline's own products along the path (no truth): share of it in the gully map
                     # (kept depth patches within the buffer) and the path length before it first enters it
                     "path_in_map_frac": float(in_map.mean()) if len(pc) else 0.0,
                     "to_first_mapped_m": first_in * step})
    return pd.DataFrame(rows)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--results", required=True)
    ap.add_argument("--members", default=None)
    ap.add_argument("--set", action="append", default=[], help="gully.automatic_heads key=value overrides")
    ap.add_argument("--out", default="results/ensemble_auto_fp")
    a = ap.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    out = REPO / a.out
    out.mkdir(parents=True, exist_ok=True)
    summ = []
    for name, files in members(a.members.split(",") if a.members else None, BASE):
        cfg = member_cfg(files)
        for kv in a.set:
            k, v = kv.split("=", 1)
            cfg["gully"]["automatic_heads"][k] = yaml.safe_load(v)
        site = Path(a.results) / cfg["site"]["name"]
        df = analyse_member(cfg, site)
        write_table(df, out / f"auto_heads_{name}.csv", floatfmt=".2f", markdown=False)
        df["member"] = name
        summ.append(df)
        f = df[df["false"]]
        log.info("%s: %d heads, %d false; false by land cover %s; FP path (mapped) %.0f m of %.0f m", name, len(df),
                 len(f), f["landcover"].value_counts().to_dict(), f["path_far_mapped_m"].sum(),
                 df["path_far_mapped_m"].sum())
    all_ = pd.concat(summ, ignore_index=True)
    all_["relief_bin"] = pd.cut(all_["relief_over_threshold"], [-np.inf, 1, 1.5, 2, 3, np.inf])
    tab = all_.groupby(["false", "landcover"]).agg(heads=("x", "size"), fp_mapped_m=("path_far_mapped_m", "sum"),
                                                   path_m=("path_m", "median"), to_nodata_m=("to_nodata_m", "median"),
                                                   relief=("relief_over_threshold", "median")).reset_index()
    write_table(tab, out / "auto_fp_summary.csv", floatfmt=".2f")
    print(tab.round(2).to_string())
    print(all_.groupby(["relief_bin", "false"], observed=True).agg(heads=("x", "size"),
                                                                    fp=("path_far_mapped_m", "sum")).to_string())
    print(all_.groupby("member").agg(heads=("x", "size"), false=("false", "sum"),
                                     fp=("path_far_mapped_m", "sum")).to_string())


if __name__ == "__main__":
    main()
