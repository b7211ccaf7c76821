#!/usr/bin/env python
"""Where each section's depth error comes from: kite DSM, plants, method (issue 16; evaluation only).

For each twin the polygons stage runs on its photogrammetric DSM (site settings, as
``benchmarks/polygons_ensemble.py``). Its t = 0.5 m polygons, pool level and rim band are then
kept, and the **same sections** are measured again (:func:`kitegully.polygons.stage.measure_morphometry`)
on the twin's true DSM and true DTM, each brought to the stage grid by the stage's own
minimum-z resampling and moving-plane fill, with the open water left empty as a photogrammetric
DSM leaves it. Per matched section, against the nearest true reach's depth (what
``morphometry_errors`` scores), the error splits exactly into

- ``e_kite_dsm`` = depth on the kite DSM − depth on the true DSM (matching: the window's fill, noise, blunders);
- ``e_plants`` = depth on the true DSM − depth on the true DTM (plants on rims and floors);
- ``e_method_on_true_dtm`` = depth on the true DTM − true depth (reference, rims, the section's
  position against the reach, the twin's rasterised V tips);

and ``e_total`` is their sum. Per twin: each part's median absolute value, and its *scatter*
(median absolute deviation of a twin's sections of one kind about their own median, averaged
over the kinds narrow U, narrow V, wide > 6 m): what no per-kind correction removes. Pooled:
each part's median per kind.

Usage::

    .venv/bin/python benchmarks/polygons_depth_sources.py --members default,ens1,h3 --out results/benchmarks/polygons_depth_sources

Writes ``<out>_sections.csv`` and ``<out>.csv`` / ``.md``. Nothing here feeds a setting of the stage.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import pandas as pd

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "src"))
sys.path.insert(0, str(REPO / "benchmarks"))

from polygons_depth_bounds import section_kinds  # noqa: E402
from polygons_ensemble import evaluate_member, member_config, water_left_empty  # noqa: E402

from kitegully.io.raster import Raster  # noqa: E402
from kitegully.polygons import PolygonParams, measure_polygons  # noqa: E402
from kitegully.polygons.dem_prep import prepare_dem  # noqa: E402
from kitegully.polygons.evaluation import observable_region_from_files  # noqa: E402
from kitegully.polygons.stage import measure_morphometry  # noqa: E402

PARTS = ["e_total", "e_kite_dsm", "e_plants", "e_method_on_true_dtm"]


def member_sections(member: str, root: Path) -> pd.DataFrame:
    """The member's matched sections with their depth on the kite DSM, the true DSM and the true DTM."""
    cfg = member_config(member)
    site, poly = root / cfg["site"]["name"], cfg["polygons"]
    truth = site / "twin" / "truth"
    p = PolygonParams.from_config(poly)
    r = Raster.read(site / "dense" / "dsm.tif")
    res = measure_polygons(r.data, r.grid, p)
    t = poly["morphometry"]["threshold_m"]
    sections = {"kite": res.sections}
    for name in ("dsm", "dtm"):
        true = water_left_empty(Raster.read(truth / f"{name}.tif"), truth)
        dem, grid, _ = prepare_dem(true.data, true.grid, p.cell_m, p.gap_neighbours, p.gap_radius_m, p.water_min_area_m2,
                                   p.window_cells * p.cell_m)
        if (grid.x0, grid.y0, grid.width, grid.height) != (res.grid.x0, res.grid.y0, res.grid.width, res.grid.height):
            raise SystemExit(f"{truth / (name + '.tif')}: its stage grid differs from the DSM's")
        sections[name] = measure_morphometry(res.labels[t], res.polygons[t], dem, res.level, res.rims, res.grid, p)[1]
    region = observable_region_from_files(res.grid, truth / "landcover.tif", truth / "landcover_classes.csv")
    scored = {k: evaluate_member(cfg, truth, res.polygons[t], s, res.grid, region)["sections"].set_index(["polygon_id", "station_m"])
              for k, s in sections.items()}
    d = scored["kite"][["shape", "width_true_m", "depth_true_m", "depth_m"]].copy()
    d["depth_true_dsm_m"] = scored["dsm"]["depth_m"].reindex(d.index)
    d["depth_true_dtm_m"] = scored["dtm"]["depth_m"].reindex(d.index)
    return d.reset_index().assign(member=member)


def split_errors(d: pd.DataFrame, wide_m: float = 6.0) -> pd.DataFrame:
    """Add the section kind and the four error parts (:data:`PARTS`) to :func:`member_sections`' table."""
    d = d.copy()
    d["kind"] = section_kinds(d, wide_m)
    d["e_total"] = d["depth_m"] - d["depth_true_m"]
    d["e_kite_dsm"] = d["depth_m"] - d["depth_true_dsm_m"]
    d["e_plants"] = d["depth_true_dsm_m"] - d["depth_true_dtm_m"]
    d["e_method_on_true_dtm"] = d["depth_true_dtm_m"] - d["depth_true_m"]
    return d


def summarise_parts(d: pd.DataFrame) -> pd.DataFrame:
    """Per twin each part's median |value| and scatter (kind-wise MAD, mean over kinds); pooled medians per kind."""
    def mad(x: pd.Series) -> float:
        return float((x - x.median()).abs().median())
    med_abs = d.groupby("member")[PARTS].agg(lambda x: x.abs().median()).add_suffix("_med_abs")
    scatter = d.groupby(["member", "kind"])[PARTS].agg(mad).groupby("member").mean().add_suffix("_scatter")
    per = pd.concat([med_abs, scatter], axis=1).reset_index()
    pooled = d.groupby("kind")[PARTS].median().add_suffix("_median").reset_index()
    pooled["member"] = f"all {d['member'].nunique()} twins, " + pooled.pop("kind")
    return pd.concat([per, pooled], ignore_index=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--root", default=str(REPO / "results"))
    ap.add_argument("--members", default="default,ens1,ens2,ens3,ens4,ens5")
    ap.add_argument("--out", default=str(REPO / "results" / "benchmarks" / "polygons_depth_sources"))
    args = ap.parse_args()
    rows = []
    for m in args.members.split(","):
        rows.append(member_sections(m, Path(args.root)))
        print(f"{m}: {len(rows[-1])} matched sections", flush=True)
    d = split_errors(pd.concat(rows, ignore_index=True).dropna(subset=["depth_m", "depth_true_m"]))
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    d.to_csv(out.with_name(out.name + "_sections.csv"), index=False)
    s = summarise_parts(d)
    s.to_csv(out.with_suffix(".csv"), index=False)
    text = ("# Polygons: the section depth error split into kite DSM, plants and method (evaluation only)\n\n"
            + s.to_markdown(index=False, floatfmt=".3f") + "\n")
    out.with_suffix(".md").write_text(text, encoding="utf-8")
    print(text)


if __name__ == "__main__":
    main()
