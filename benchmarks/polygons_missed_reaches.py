#!/usr/bin/env python
"""Where the wide gullies' missed cells lie, with the stage's current code (evaluation only; issue 16 IoU).

For each member's photogrammetric DSM (as ``polygons_ensemble.py``) the stage is run, and the true
cells of the gullies wider than ``polygons.evaluation.wide_gully_m`` (the observable truth) that the
t = ``morphometry.threshold_m`` polygons miss are split by their distance to the nearest polygon cell:
within 1 m (the outline lies inside the rims), 1–3 m, and farther than 3 m (whole reaches without a
polygon). For the far ones: the share with a thalweg line within 3 m, with a transect within 1 m, with
any fill depth (> 0.01 m) and with a fill depth of at least t on the conditioned DEM; and the median
maximum depth of the true gullies they belong to (so whether they are shallow reaches).

    .venv/bin/python benchmarks/polygons_missed_reaches.py [--members default,ens1,...] [--out results/benchmarks/polygons_missed_reaches]

Writes ``<out>.csv`` (one row per member).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import scipy.ndimage as ndi

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "src"))
sys.path.insert(0, str(REPO / "benchmarks"))

import polygons_ensemble as pe  # noqa: E402
from kitegully.io.raster import Raster  # noqa: E402
from kitegully.io.vectors import read_vector  # noqa: E402
from kitegully.polygons import PolygonParams, measure_polygons  # noqa: E402
from kitegully.polygons.evaluation import clip_truth, observable_region_from_files, rasterize, truth_table  # noqa: E402


def _near(gdf, grid, distance_m: float) -> np.ndarray:
    """Cells within ``distance_m`` of the lines of ``gdf`` (all False when it is empty)."""
    if len(gdf) == 0:
        return np.zeros((grid.height, grid.width), bool)
    return rasterize(gdf.geometry.buffer(distance_m), grid).astype(bool)


def missed_cells(member: str, root: Path) -> dict:
    """The split of one member's missed wide-gully cells (see the module docstring)."""
    cfg = pe.member_config(member)
    site = root / cfg["site"]["name"]
    truth = site / "twin" / "truth"
    poly = cfg["polygons"]
    dem = Raster.read(site / "dense" / "dsm.tif")
    res = measure_polygons(dem.data, dem.grid, PolygonParams.from_config(poly), dem_name=str(site / "dense" / "dsm.tif"))
    grid, t = res.grid, poly["morphometry"]["threshold_m"]
    region = observable_region_from_files(grid, truth / "landcover.tif", truth / "landcover_classes.csv")
    polys, lines = clip_truth(read_vector(truth / "gully_polygons.gpkg"), read_vector(truth / "gully_centrelines.gpkg"), region)
    table = truth_table(lines, polys, cfg["twin"]["gullies"]["u_shape_exponent"])
    wide = table.loc[table["mean_width_m"] > poly["evaluation"]["wide_gully_m"], "gully_id"].to_numpy()
    lab = rasterize(polys.geometry, grid, values=(polys["gully_id"].to_numpy() + 1).tolist(), dtype=np.int32)
    true_wide = np.isin(lab, wide + 1)
    mapped = rasterize(res.polygons[t].geometry, grid).astype(bool)
    missed = true_wide & ~mapped
    to_polygon = ndi.distance_transform_edt(~mapped) * grid.cell
    far = missed & (to_polygon > 3.0)
    depth = table.set_index(table["gully_id"] + 1)["max_depth_m"]
    n, nf = max(int(missed.sum()), 1), max(int(far.sum()), 1)
    return {"member": member, "wide_cells": int(true_wide.sum()), "recall_wide": 1.0 - missed.sum() / max(true_wide.sum(), 1),
            "missed_within_1m_pct": 100 * (missed & (to_polygon <= 1.0)).sum() / n,
            "missed_1_to_3m_pct": 100 * (missed & (to_polygon > 1.0) & (to_polygon <= 3.0)).sum() / n,
            "missed_beyond_3m_pct": 100 * far.sum() / n,
            "beyond_3m_thalweg_within_3m_pct": 100 * (far & _near(res.thalweg, grid, 3.0)).sum() / nf,
            "beyond_3m_transect_within_1m_pct": 100 * (far & _near(res.transects, grid, 1.0)).sum() / nf,
            "beyond_3m_any_fill_depth_pct": 100 * (far & (res.fill_depth > 0.01)).sum() / nf,
            "beyond_3m_fill_depth_ge_t_pct": 100 * (far & (res.fill_depth >= t)).sum() / nf,
            "beyond_3m_gully_max_depth_median_m": float(np.nanmedian(depth.reindex(lab[far]).to_numpy())) if far.any() else np.nan,
            "wide_gully_max_depth_median_m": float(table.loc[table["gully_id"].isin(wide), "max_depth_m"].median())}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--root", default=str(REPO / "results"))
    ap.add_argument("--members", default="default,ens1,ens2,ens3,ens4,ens5")
    ap.add_argument("--out", default=str(REPO / "results" / "benchmarks" / "polygons_missed_reaches"))
    a = ap.parse_args()
    df = pd.DataFrame([missed_cells(m, Path(a.root)) for m in a.members.split(",")])
    out = Path(a.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    df.to_csv(out.with_suffix(".csv"), index=False)
    print(df.round(3).to_string(index=False))


if __name__ == "__main__":
    main()
