"""Controlled check of the change stage: both epochs' errors follow the stated noise model.

Takes the DEM-site example's settings (``config/sites/kamech_dem_change.yaml``) but not its
photogrammetric DSMs: epoch 2 is the twin's epoch-2 truth plus a stated noise model
(``python -m kitegully.change.example`` writes it) and epoch 1 the epoch-1 truth DSM seen
through the same noise model (another seed, no georeferencing error:
``kitegully.change.example.CONTROLLED_EPOCH1``), so what is left is the method's own error.

Usage (after the default twin and the DEM-site example inputs exist):
``.venv/bin/python benchmarks/change_controlled.py`` → ``benchmarks/out/change_controlled/``.
"""

from __future__ import annotations

import copy
import logging
from pathlib import Path

import yaml

from kitegully.change.evaluation import evaluate_change
from kitegully.change.example import CONTROLLED_EPOCH1, export_epoch
from kitegully.change.params import THRESHOLD_METHODS, ChangeParams
from kitegully.change.stage import detect_change, output_paths

REPO = Path(__file__).resolve().parents[1]
OUT = REPO / "benchmarks" / "out" / "change_controlled"

EVAL = dict(detection="detection.csv", budget_vs_truth="budget_vs_truth.csv", headcuts_vs_truth="headcut_retreat_vs_truth.csv",
            moritani_plots="moritani_plots.csv", summary="evaluation_summary.csv",
            widening_vs_truth="widening_vs_truth.csv")


def main() -> None:
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s: %(message)s")
    cfg = yaml.safe_load((REPO / "config/sites/kamech_dem_change.yaml").read_text())
    ch = copy.deepcopy(cfg["change"])
    ev = ch["evaluation"]
    e1 = export_epoch(REPO / ev["dem1_truth"], OUT / "inputs/epoch1_dsm_model.tif", CONTROLLED_EPOCH1)
    ch["epochs"][0]["dem"] = str(e1)
    # epoch 2: the twin's epoch-2 truth through the same stated noise model (python -m kitegully.change.example),
    # not the site's photogrammetric epoch 2, so that both epochs' errors follow the model
    ch["epochs"][1].update(dem="results/kamech_dem_change/inputs/epoch2_dsm.tif", correlation=None)
    ch["epochs"][0]["correlation"] = None
    out = output_paths(OUT)
    params = ChangeParams.from_config({k: ch[k] for k in ("coregistration", "thresholds", "budget", "headcuts", "widening")},
                                      seed=cfg["seed"])
    detect_change(ch["epochs"], ch["masks"], ch["heads_file"], params, out, cfg["site"]["crs"], ch["figure"],
                  sections_path=ch.get("sections_file"))
    evaluate_change(out["dod"], out["sigma_dod"], {m: out[f"thresholded_{m}"] for m in THRESHOLD_METHODS},
                    ev["dem1_truth"], ev["dem2_truth"], ch["masks"], out["budget"], out["headcuts"], ev["heads1_truth"],
                    ev["heads2_truth"], {k: ev[k] for k in ("plot_m", "min_lowering_m", "head_match_m", "net_tolerance")},
                    {k: str(OUT / v) for k, v in EVAL.items()},
                    widening=(out["widening"], ev.get("polygons1_truth"), ev.get("polygons2_truth"), params.widening_margin_m,
                              ch.get("sections_file")))


if __name__ == "__main__":
    main()
