#!/usr/bin/env python
"""The polygons stage on a site like the paper's: one large gully system in a peat valley (issue 16).

Höfle et al. (2013) mapped one branching gully system cut into a nearly level cushion
peatland (widths 3.5–51 m, maximum depths 2.4–7.5 m, 6 919–8 773 m² of gully) from a TLS
DTM at 0.5 m. This script builds such a DTM with known gullies and runs the stage on it:

- plateau: 1 % down-valley, rising 2 % to the valley sides, smooth micro-relief of 0.1 m;
- gullies (carved exactly as the twin carves, ``kitegully.twin.gullies.carve``): a
  meandering main channel widening from 8 to 45 m and deepening from 2.4 to 6 m, U-shaped
  (p = 4), with three tributaries 3.5–10 m wide and 2.4–3.5 m deep;
- TLS-like survey: white noise of SD 0.034 m (the paper's registration SD) and 3 % of the
  cells empty in small clusters (occlusion), filled by the stage's moving planes.

The site itself is now ``config/sites/peat_valley.yaml`` (a DEM twin run through Snakemake);
this script builds the same DTM (``kitegully.twin.peat_valley``) and runs the stage with the
site's polygons settings in one process; scores, morphometry errors and Table 1 are computed
as the twin evaluation rules do.

Usage::

    .venv/bin/python benchmarks/polygons_peat_valley.py [--seed 2013] [--survey-edge site|on|off]

Results are printed and written to ``results/benchmarks/polygons_peat_valley.md``.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from kitegully.config import load_yaml
from kitegully.io.raster import GridSpec
from kitegully.polygons.evaluation import evaluate_against_truth, regenerate_table1
from kitegully.polygons.stage import PolygonParams, measure_polygons
from kitegully.twin.gullies import Gully
from kitegully.twin.peat_valley import PeatValleyParams, make_peat_valley
from kitegully.twin.gully_truth import centrelines, polygons

REPO = Path(__file__).resolve().parents[1]
CRS = "EPSG:32718"
U_EXPONENT = 4.0


def build_site(seed: int) -> tuple[np.ndarray, GridSpec, list[Gully]]:
    """The peat-valley DTM (m, NaN = occluded) and its gullies: the site's DEM twin (kitegully.twin.peat_valley)."""
    site = load_yaml(REPO / "config" / "sites" / "peat_valley.yaml")
    twin = make_peat_valley(PeatValleyParams.from_config(site["dem_twin"]), seed, CRS)
    return twin.observed.data, twin.observed.grid, twin.gullies


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seed", type=int, default=2013)
    ap.add_argument("--out", default=str(REPO / "results" / "benchmarks" / "polygons_peat_valley.md"))
    ap.add_argument("--survey-edge", choices=["site", "on", "off"], default="site",
                    help="polygons.transects.survey_edge: the site's setting, or forced on / off (to compare)")
    args = ap.parse_args()
    cfg = load_yaml(REPO / "config" / "sites" / "peat_valley.yaml")["polygons"]  # the site's settings (40 m transects, TCI > 9 [P])
    if args.survey_edge != "site":
        cfg["transects"]["survey_edge"] = args.survey_edge == "on"
    dtm, grid, gullies = build_site(args.seed)
    truth_cl = centrelines(gullies, 0.1, 10.0, CRS)
    truth_poly = polygons(gullies, 0.1, CRS)
    t0 = time.perf_counter()
    res = measure_polygons(dtm, grid, PolygonParams.from_config(cfg), dem_name="peat-valley DTM")
    t_run = time.perf_counter() - t0
    ev = evaluate_against_truth(res.polygons[0.5], res.sections, truth_poly, truth_cl, res.grid, cfg["evaluation"], U_EXPONENT)
    stats, comp, ops = regenerate_table1(res.polygons, truth_poly, truth_cl, res.grid, cfg["evaluation"]["operators"], args.seed, U_EXPONENT)
    sc = ev["scores"].set_index("kind")
    lines = [
        f"# Polygons stage on a peat-valley DTM like the paper's (seed {args.seed}; survey-edge dams "
        f"{'on' if cfg['transects'].get('survey_edge') else 'off'})", "",
        f"{grid.height} x {grid.width} cells of {grid.cell} m; {int(np.isnan(dtm).sum())} occluded cells; true gully area "
        f"{truth_poly['area_m2'].sum():.0f} m² (paper 6 919–8 773 m²), widths {min(g.width.min() for g in gullies):.1f}–"
        f"{max(g.width.max() for g in gullies):.1f} m, depths {min(g.depth.min() for g in gullies):.1f}–{max(g.depth.max() for g in gullies):.1f} m; "
        f"stage run {t_run:.1f} s.", "",
        "## Against the true gullies (t = 0.5 m)", "",
        "| set | recall | precision | IoU |", "|---|---|---|---|",
        *[f"| {k} | {sc.loc[k, 'recall']:.3f} | {sc.loc[k, 'precision']:.3f} | {sc.loc[k, 'iou']:.3f} |" for k in ("all", "wide")], "",
        ev["errors"].to_markdown(index=False, floatfmt=".3f"), "",
        "## Paper Table 1 regenerated", "", stats.to_markdown(index=False, floatfmt=".1f"), "",
        comp.to_markdown(index=False, floatfmt=".1f"), "",
        "## Polygon areas by threshold", "",
        "| t (m) | polygons | area (m²) |", "|---|---|---|",
        *[f"| {t:g} | {len(g)} | {g['area_m2'].sum():.0f} |" for t, g in sorted(res.polygons.items())],
    ]
    text = "\n".join(lines) + "\n"
    print(text)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(text, encoding="utf-8")


if __name__ == "__main__":
    main()
