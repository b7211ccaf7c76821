#!/usr/bin/env python
"""Why the polygons stage's depth, volume and IoU errors are larger on the photogrammetric DSM (issue 16).

For each ensemble member (as ``benchmarks/polygons_ensemble.py``: ``<root>/<site>/dense/dsm.tif``
and ``<root>/<site>/twin/truth/``), the stage runs on the DSM once; its t = 0.5 m polygons and
rims are then kept and the cross-sections re-draped on three surfaces, all brought to the stage
grid by the stage's own minimum-z resampling:

- ``dsm``: the photogrammetric DSM (what the stage measures);
- ``true_dsm``: the twin's true DSM (ground + shrubs and trees, no matching error);
- ``true_dtm``: the twin's true ground.

``dsm - true_dsm`` is the matching error, ``true_dsm - true_dtm`` the vegetation's. The script
also reports the median height of the DSM above the true ground on the rims (breakline band
within the rim search of a polygon) and on the polygon floors (cells at least 1 m inside), the
volume of sections with no true reach within the match distance (false polygons), and for the
gullies wider than 2 m the recall and precision of the polygon cells in their zone.

Diagnosis only: it reads the truth, and nothing here feeds a setting of the stage.

Usage::

    .venv/bin/python benchmarks/polygons_dsm_diagnosis.py --root results [--members default,ens4]

Writes ``results/benchmarks/polygons_dsm_diagnosis.csv`` and ``.md``.
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

from polygons_ensemble import ENSEMBLE_DIR, member_config  # noqa: E402

from kitegully.io.raster import Raster  # noqa: E402
from kitegully.io.vectors import read_vector  # noqa: E402
from kitegully.polygons.evaluation import observable_region_from_files  # noqa: E402
from kitegully.polygons import PolygonParams, evaluate_against_truth, measure_polygons  # noqa: E402
from kitegully.polygons.conditioning import barrier_mask  # noqa: E402
from kitegully.polygons.dem_prep import min_z_resample  # noqa: E402
from kitegully.polygons.morphometry import measure_sections  # noqa: E402


def _on_stage_grid(path: Path, cell: float) -> np.ndarray:
    r = Raster.read(path)
    z, _ = min_z_resample(r.data, r.grid, cell)
    return z


def diagnose(member: str, root: Path) -> list[dict]:
    cfg = member_config(member)
    poly = cfg["polygons"]
    site = root / cfg["site"]["name"]
    truth = site / "twin" / "truth"
    p = PolygonParams.from_config(poly)
    r = Raster.read(site / "dense" / "dsm.tif")
    res = measure_polygons(r.data, r.grid, p, dem_name=member)
    t_poly, t_cl = read_vector(truth / "gully_polygons.gpkg"), read_vector(truth / "gully_centrelines.gpkg")
    evcfg = {k: v for k, v in poly["evaluation"].items() if k != "operators"}
    u_exp = cfg["twin"]["gullies"]["u_shape_exponent"]
    thr = p.morph_threshold_m
    lab = res.labels[thr]
    rims = barrier_mask(res.breakline_cells, np.zeros_like(res.breakline_cells), p.grow_cells)
    level = res.fill_depth + res.dem  # only for reference="spill"
    surfaces = {"dsm": res.dem, "true_dsm": _on_stage_grid(truth / "dsm.tif", p.cell_m), "true_dtm": _on_stage_grid(truth / "dtm.tif", p.cell_m)}
    h, w = lab.shape
    for k in surfaces:
        surfaces[k] = surfaces[k][:h, :w]
    # the truth a survey can see (outside the reservoir), as the polygons_evaluate rule
    region = observable_region_from_files(res.grid, truth / "landcover.tif", truth / "landcover_classes.csv")
    rows = []
    base = None
    for name, z in surfaces.items():
        zf = np.where(np.isfinite(z), z, res.dem)
        _, sec, _ = measure_sections(lab, res.polygons[thr], zf, level, res.grid, p.section_spacing_m, p.reference, p.smooth_step_m,
                                     p.snakes_alpha, p.snakes_beta, p.branches, rims, p.rim_search_m, p.prolong_axes,
                                     p.ground_segment_m)
        ev = evaluate_against_truth(res.polygons[thr], sec, t_poly, t_cl, res.grid, evcfg, u_exp, region=region)
        e = ev["errors"].set_index("quantity")
        per = ev["sections"]
        tot = float((sec["area_m2"] * sec["slab_m"]).sum())
        matched = float((per["area_m2"] * per["slab_m"]).sum())
        row = {"member": member, "surface": name, "sections": len(sec), "matched": len(per),
               "depth_med_abs_m": e.loc["depth (m)", "median_abs_error"], "depth_bias_m": e.loc["depth (m)", "median_error"],
               "area_med_err_m2": e.loc["area (m2)", "median_error"],
               "volume_error_pct": e.loc["volume, all sections vs all true gullies (m3)", "error_pct"],
               "unmatched_volume_m3": tot - matched, "true_volume_m3": e.loc["volume, all sections vs all true gullies (m3)", "true"],
               "matched_volume_error_pct": 100 * (matched - e.loc["volume, all sections vs all true gullies (m3)", "true"])
               / e.loc["volume, all sections vs all true gullies (m3)", "true"]}
        if base is None:
            sc = ev["scores"].set_index("kind")
            row.update({"iou_wide": sc.loc["wide", "iou"], "recall_wide": sc.loc["wide", "recall"], "precision_wide": sc.loc["wide", "precision"],
                        "width_bias_m": e.loc["width (m)", "median_error"], "width_med_abs_m": e.loc["width (m)", "median_abs_error"]})
            base = ev
        rows.append(row)
    # where the DSM stands above the true ground: rims near polygons and polygon floors
    near = ndi.distance_transform_edt(lab == 0, sampling=p.cell_m) <= p.rim_search_m
    inside = ndi.distance_transform_edt(lab > 0, sampling=p.cell_m) >= 1.0
    dz = surfaces["dsm"] - surfaces["true_dtm"]
    veg = surfaces["true_dsm"] - surfaces["true_dtm"]
    for row in rows:
        row.update({"rim_dsm_above_ground_m": float(np.nanmedian(dz[rims & near & (lab == 0)])),
                    "rim_veg_m": float(np.nanmedian(veg[rims & near & (lab == 0)])),
                    "rim_veg_share_gt_0.1": float(np.nanmean(veg[rims & near & (lab == 0)] > 0.1)),
                    "floor_dsm_above_ground_m": float(np.nanmedian(dz[inside])),
                    "floor_veg_m": float(np.nanmedian(veg[inside]))})
    per = base["sections"]
    print(member, "largest unmatched/over-volume polygons:")
    vol = base["volumes"].sort_values("volume_m3", ascending=False).head(5)
    print(vol.to_string())
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--root", default=str(REPO / "results"))
    ap.add_argument("--members", default="default," + ",".join(p.stem for p in sorted(ENSEMBLE_DIR.glob("*.yaml"))))
    ap.add_argument("--out", default=str(REPO / "results" / "benchmarks" / "polygons_dsm_diagnosis"))
    args = ap.parse_args()
    rows = []
    for m in args.members.split(","):
        rows += diagnose(m, Path(args.root))
        print(pd.DataFrame(rows[-3:]).to_string(), flush=True)
    df = pd.DataFrame(rows)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    df.to_csv(out.with_suffix(".csv"), index=False)
    out.with_suffix(".md").write_text("# Polygons on the DSM: where the errors come from\n\n" + df.to_markdown(index=False, floatfmt=".3g") + "\n",
                                      encoding="utf-8")


if __name__ == "__main__":
    main()
