"""Does a narrower window in the last dense pass resolve narrow gullies? (evaluation only)

The dense matcher correlates 5 × 5-cell windows (1 m at 0.2 m cells): a gully floor or head
narrower than that is smoothed into its banks, and a DSM cell whose window holds part of a
crown carries the crown's height. With ``final_passes: 2`` the last pass only searches a few
elevation steps around a surface the 5 × 5 window has already fixed, so a smaller window there
(``dense.matching.final_window_half_cells``) may sharpen narrow relief without the blunders a
small window gives in a full search.

This script matches boxes around the default twin's true gully heads with the site's matcher
settings and with the last pass's window changed, on its georeferenced model (the products of a
default run: ``results/kamech_twin/georef`` and ``sfm/work``; an ensemble member's with
``--results results/ens3``), and scores each DSM against the twin's true DSM by land cover
(evaluation only: the truth is read here, never in a rule):

- median and NMAD of DSM − true DSM on open ground (bare, ploughed, grass: noise and bias);
- the same on gully cells (a positive median = floor raised by the window);
- the depth of the gully cells below the open ground within 3 m, DSM against truth
  (median ratio: 1 = the incision is resolved, 0 = smoothed away), for all gully cells and for
  the narrow reaches (local half-width ≤ 0.75 m: heads and narrow floors, 0.3–1.5 m wide);
- valid cells (all, and in the narrow reaches), wall time (one thread).

    .venv/bin/python benchmarks/dense_final_window.py [--results results/kamech_twin] [--boxes 32]
        [--variant "site:" --variant "w3:final_window_half_cells=1" --variant "NAME:p2=0.06,..."]

Writes ``benchmarks/out/dense_final_window.csv`` (one row per box and variant) and
``dense_final_window_summary.csv`` / ``.md`` (medians over the boxes per variant).
"""

from __future__ import annotations

import argparse
import logging
import sys
import time
from dataclasses import replace
from pathlib import Path

import geopandas as gpd
import numpy as np
import pandas as pd
import scipy.ndimage as ndi
import yaml

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "src"))

from kitegully.dense.matching import MatchParams  # noqa: E402
from kitegully.dense.surface import dense_surface  # noqa: E402
from kitegully.dense.views import read_offset, views_from_reconstruction  # noqa: E402
from kitegully.io.raster import GridSpec, read_raster  # noqa: E402
from kitegully.io.tables import write_table  # noqa: E402

log = logging.getLogger("dense_final_window")
OPEN = (1, 2, 3)  # bare eroded, ploughed, grass (twin landcover codes)
GULLY = 9


def nmad(x: np.ndarray) -> float:
    x = x[np.isfinite(x)]
    return float(1.4826 * np.median(np.abs(x - np.median(x)))) if x.size else float("nan")


def score_box(dsm: np.ndarray, true: np.ndarray, lc: np.ndarray, cell: float) -> dict:
    """DSM − truth by land cover, and the gully cells' depth below the open ground within 3 m."""
    err = dsm - true
    open_ = np.isin(lc, OPEN)
    gully = lc == GULLY
    row = {
        "valid_pct": 100.0 * float(np.isfinite(dsm).mean()),
        "open_median_m": float(np.nanmedian(err[open_])) if open_.any() else np.nan,
        "open_nmad_m": nmad(err[open_]),
        "gully_cells": int(gully.sum()),
        "gully_median_m": float(np.nanmedian(err[gully])) if gully.any() else np.nan,
        "gully_nmad_m": nmad(err[gully]),
    }
    # local open-ground level: median of the open cells within 3 m (a percentile filter ignores NaN poorly,
    # so the open cells' values are averaged with a normalised box)
    r = int(round(3.0 / cell))
    size = 2 * r + 1

    def open_level(z):
        w = (open_ & np.isfinite(z)).astype(np.float64)
        s = ndi.uniform_filter(np.where(w > 0, z, 0.0), size) / np.maximum(ndi.uniform_filter(w, size), 1e-9)
        return np.where(ndi.uniform_filter(w, size) > 0.05, s, np.nan)

    d_true = open_level(true) - true
    d_dsm = open_level(dsm) - dsm
    # narrow reaches: the gully's local half-width (largest distance to its edge within 1.4 m) <= 0.75 m
    half_width = ndi.maximum_filter(ndi.distance_transform_edt(gully) * cell, size=int(round(1.4 / cell)) | 1)
    for name, part in (("gully", gully), ("narrow", gully & (half_width <= 0.75))):
        sel = part & np.isfinite(d_true) & np.isfinite(d_dsm) & (d_true > 0.2)
        row[f"{name}_depth_cells"] = int(sel.sum())
        row[f"{name}_true_depth_median_m"] = float(np.median(d_true[sel])) if sel.any() else np.nan
        row[f"{name}_dsm_depth_median_m"] = float(np.median(d_dsm[sel])) if sel.any() else np.nan
        row[f"{name}_depth_ratio_median"] = float(np.median(d_dsm[sel] / d_true[sel])) if sel.any() else np.nan
        row[f"{name}_valid_pct"] = 100.0 * float(np.isfinite(dsm[part]).mean()) if part.any() else np.nan
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--results", default=str(REPO / "results/kamech_twin"))
    ap.add_argument("--site", default=str(REPO / "config/sites/kamech_twin.yaml"))
    ap.add_argument("--boxes", type=int, default=32, help="boxes centred on this many true gully heads, spread evenly")
    ap.add_argument("--box-cells", type=int, default=256)
    ap.add_argument("--variant", action="append", default=[],
                    help="NAME:key=value[,key=value] MatchParams overrides (yaml values); 'site:' = none. "
                         "Default: site and w3 (final_window_half_cells=1)")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--out", default=str(REPO / "benchmarks/out/dense_final_window"))
    a = ap.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    import numba
    import pycolmap

    numba.set_num_threads(a.threads)
    res = Path(a.results)
    cfg = yaml.safe_load(Path(a.site).read_text())["dense"]
    mp = MatchParams.from_config(cfg["matching"])
    rec = pycolmap.Reconstruction(str(res / "georef/model"))
    views = views_from_reconstruction(rec, res / "sfm/work/images", read_offset(res / "georef/transform.json"),
                                      where=str(res / "georef/model"))
    true, grid = read_raster(res / "twin/truth/dsm.tif")
    lc, _ = read_raster(res / "twin/truth/landcover.tif")
    heads = gpd.read_file(res / "twin/truth/gully_heads.gpkg").sort_values("gully_id")
    heads = heads.iloc[np.linspace(0, len(heads) - 1, a.boxes).round().astype(int)]
    n = a.box_cells
    variants = [(v.split(":", 1)[0], {kv.split("=")[0]: yaml.safe_load(kv.split("=")[1])
                                      for kv in v.split(":", 1)[1].split(",") if kv})
                for v in (a.variant or ["site:", "w3:final_window_half_cells=1"])]
    rows = []
    for _, h in heads.iterrows():
        c = int((h.geometry.x - grid.x0) / grid.cell) - n // 2
        r = int((grid.y0 - h.geometry.y) / grid.cell) - n // 2
        r, c = int(np.clip(r, 0, grid.height - n)), int(np.clip(c, 0, grid.width - n))
        box = GridSpec(grid.x0 + c * grid.cell, grid.y0 - r * grid.cell, grid.cell, n, n, grid.crs)
        t_box, lc_box = true[r:r + n, c:c + n], lc[r:r + n, c:c + n]
        for name, over in variants:
            p = replace(mp, **over)
            t0 = time.perf_counter()
            d = dense_surface(views, box, p, int(cfg["tile_cells"]), int(cfg["overlap_cells"]),
                              int(cfg["max_cached_images"])).dsm
            wall = time.perf_counter() - t0
            row = {"gully_id": int(h.gully_id), "row": r, "col": c, "variant": name,
                   "wall_s": round(wall, 1), **score_box(d, t_box, lc_box, grid.cell)}
            log.info("%s", {k: (round(v, 3) if isinstance(v, float) else v) for k, v in row.items()})
            rows.append(row)
    df = pd.DataFrame(rows)
    out = Path(a.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    df.to_csv(out.with_suffix(".csv"), index=False)
    summ = df.groupby("variant", sort=False).agg(
        boxes=("gully_id", "size"), wall_s=("wall_s", "sum"), valid_pct=("valid_pct", "mean"),
        open_median_m=("open_median_m", "median"), open_nmad_m=("open_nmad_m", "median"),
        gully_median_m=("gully_median_m", "median"), gully_nmad_m=("gully_nmad_m", "median"),
        gully_true_depth_median_m=("gully_true_depth_median_m", "median"),
        gully_dsm_depth_median_m=("gully_dsm_depth_median_m", "median"),
        gully_depth_ratio_median=("gully_depth_ratio_median", "median"),
        narrow_cells=("narrow_depth_cells", "sum"), narrow_valid_pct=("narrow_valid_pct", "mean"),
        narrow_true_depth_median_m=("narrow_true_depth_median_m", "median"),
        narrow_dsm_depth_median_m=("narrow_dsm_depth_median_m", "median"),
        narrow_depth_ratio_median=("narrow_depth_ratio_median", "median")).reset_index()
    write_table(summ.round(3), out.parent / f"{out.name}_summary.csv")
    print(summ.round(3).to_string(index=False))


if __name__ == "__main__":
    main()
