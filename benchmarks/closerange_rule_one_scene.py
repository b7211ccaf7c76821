"""One close-range scene end to end with this branch's code: photos rendered, SfM, spheres, dense, rule (issue 20).

The library entry points of ``closerange_photos`` and ``closerange_sfm`` (no Snakemake),
with the site's config and seed, the OBIA scene inputs read from ``--results`` (read only),
outputs under ``--out/<scene>``.  Prints the record's rule and marker numbers and the rule's
truth.  Cost: the scene's share of ``make closerange`` (~2–4 CPU-min).

Usage (repository root, PYTHONPATH=src):
    python benchmarks/closerange_rule_one_scene.py --scene scene_05 [--results ...] [--out results/kamech_twin/closerange_rule/run]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))
from closerange_rule_scene import REPO, site_config, stage_params  # noqa: E402

from kitegully.closerange.stage import photogrammetric_orthophoto, photograph_scene  # noqa: E402
from kitegully.io.raster import read_raster  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--scene", default="scene_05")
    ap.add_argument("--results", default="/work/wt/closerange9/results/kamech_twin")
    ap.add_argument("--site", default="kamech_twin")
    ap.add_argument("--out", default=str(REPO / "results" / "kamech_twin" / "closerange_rule" / "run"))
    ap.add_argument("--threads", type=int, default=2)
    a = ap.parse_args()
    cfg = site_config(a.site)
    cr = cfg["closerange"]
    od = Path(a.results) / "obia" / "scenes" / a.scene
    out = Path(a.out) / a.scene
    out.mkdir(parents=True, exist_ok=True)
    meta = json.loads((od / "truth" / "scene.json").read_text())
    markers = pd.read_csv(od / "markers.csv")
    truth = photograph_scene(str(od / "orthophoto.tif"), str(od / "dem.tif"), str(od / "truth" / "markers.tif"),
                             str(od / "truth" / "eroded.tif"), meta, markers, cr["walk"],
                             float(cfg["obia"]["scenes"]["marker_radius_m"]), a.scene not in cr["scenes_without_rule"],
                             cfg["seed"], a.scene, out / "photos")
    (out / "walk_truth.json").write_text(json.dumps(truth))
    _, grid = read_raster(od / "dem.tif")
    paths = {k: str(out / v) for k, v in {"model": "model", "summary": "sfm_summary.json", "images": "sfm_images.csv",
                                          "image_info": "image_info.json", "orthophoto": "orthophoto.tif", "dem": "dem.tif",
                                          "spheres": "sphere_residuals.csv"}.items()}
    record = photogrammetric_orthophoto(out / "photos", markers, str(od / "markers.csv"), grid, cfg["sfm"], stage_params(cfg),
                                        cfg["seed"], a.threads, a.scene, out / "sfm_work", paths)
    (out / "closerange.json").write_text(json.dumps(record, indent=1))
    r = record.get("rule") or {}
    print(json.dumps({"scene": a.scene, "images_aligned": record["images_aligned"], "marker_error_m": record["marker_error_m"],
                      "scale_error_pct": record["scale_error_pct"], "rule_method": record["rule_method"],
                      "legs_m": [r.get("leg_a_m"), r.get("leg_b_m")], "photos": [r.get("photos_corner"), r.get("photos_a"), r.get("photos_b")],
                      "timings_s": record["timings_s"], "render_s": truth["render_s"]}, indent=1))


if __name__ == "__main__":
    main()
