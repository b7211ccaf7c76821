"""The twin's second survey (issue 17): flight -> inputs -> sfm -> georef -> dense -> validate
run as the {epoch} wildcard of the same rules, epoch 1 at its old paths, epoch 2 one folder
down; the change stage compares the two photogrammetric DSMs."""

from __future__ import annotations

import re
from pathlib import Path

import pandas as pd
import pytest

from snakemake_utils import REPO, run_snakemake

TINY = REPO / "config" / "sites" / "tiny_twin.yaml"
PER_EPOCH = ["flight_simulate", "flight_render", "flight_figures", "check_inputs", "sfm_reconstruct", "georef_adjust",
             "georef_evaluate", "dense_match", "validate_checkpoints", "validate_truth"]


def _job_counts(text: str) -> dict[str, int]:
    block = text.split("Job stats:", 1)[1]
    return {m.group(1): int(m.group(2)) for m in re.finditer(r"^(\w+)\s+(\d+)\s*$", block, re.M)}


def test_dry_run_runs_each_chain_rule_once_per_epoch(tmp_path):
    res = tmp_path / "results"
    proc = run_snakemake(TINY, res, extra=["-n"])
    out = proc.stdout + proc.stderr
    counts = _job_counts(out)
    for rule in PER_EPOCH:
        assert counts.get(rule) == 2, (rule, counts)
    assert counts.get("change_detect") == 1 and counts.get("change_evaluate") == 1
    site = res / "tiny_twin"
    # epoch 1 keeps the paths it always had; epoch 2 lives under epoch2/ (outputs, logs, benchmarks)
    for p in ("flight/observed/images", "flight/epoch2/observed/images", "dense/dsm.tif", "dense/epoch2/dsm.tif",
              "validate/checkpoint_summary.csv", "validate/epoch2/checkpoint_summary.csv",
              "logs/flight/epoch2/flight_render.log", "benchmarks/dense/epoch2/dense_match.tsv",
              "benchmarks/dense/dense_match.tsv"):
        assert str(site / p) in out, p
    # epoch 2 is flown over epoch 2's twin, and the change stage reads both dense DSMs
    assert str(site / "twin/epoch2/truth/texture.tif") in out
    detect = re.split(r"\n\[|\n\n", out.split("rule change_detect:", 1)[1], maxsplit=1)[0]
    assert str(site / "dense/dsm.tif") in detect and str(site / "dense/epoch2/dsm.tif") in detect
    assert str(site / "gully/gully_polygons.gpkg") in detect and str(site / "obia/kite/bare_soil.gpkg") in detect
    assert "twin/truth" not in detect and "twin/epoch2/truth" not in detect  # truth only in change_evaluate


def check_tiny_twin_change(site: Path) -> None:
    """Assertions on a finished tiny-twin run (used by the slow test; also callable on results/)."""
    for e in ("", "epoch2/"):
        for p in ("flight/flight_summary.csv", "georef/summary.json", "dense/dsm.tif", "validate/checkpoint_summary.csv"):
            assert (site / p.replace("/", f"/{e}", 1)).is_file(), e + p
    f1 = pd.read_csv(site / "flight/flight_summary.csv").set_index("quantity")["value"]
    f2 = pd.read_csv(site / "flight/epoch2/flight_summary.csv").set_index("quantity")["value"]
    t1 = pd.read_csv(site / "twin/truth/targets.csv")
    t2 = pd.read_csv(site / "twin/epoch2/truth/targets.csv")
    assert len(t2) == len(t1) - 1  # tiny_twin: twin.epoch2.targets_lost 1
    assert f2["gcp_targets_digitised"] <= len(t2)
    assert f1["images"] > 0 and f2["images"] > 0
    for name in ("dod.tif", "dod_thresholded_probabilistic.tif", "budget.csv", "headcut_retreat.csv", "dod_map.png",
                 "detection.csv", "budget_vs_truth.csv", "evaluation_summary.csv"):
        assert (site / "change" / name).is_file(), name
    budget = pd.read_csv(site / "change/budget.csv")
    assert {"site", "gully", "bare_soil"} <= set(budget["mask"].astype(str).str.split(":").str[0])


@pytest.mark.slow
def test_tiny_twin_two_surveys_and_change(tmp_path):
    res = tmp_path / "results"
    site = res / "tiny_twin"
    run_snakemake(TINY, res, [str(site / "change/evaluation_summary.csv"), str(site / "validate/checkpoint_summary.csv"),
                              str(site / "validate/epoch2/checkpoint_summary.csv")], cores=2)
    check_tiny_twin_change(res / "tiny_twin")


def test_dem_site_cannot_use_the_twins_null_paths(tmp_path):
    import yaml

    cfg = yaml.safe_load((REPO / "config/sites/kamech_dem_change.yaml").read_text(encoding="utf-8"))
    cfg["change"]["evaluation"]["dem2_truth"] = None
    site = tmp_path / "site.yaml"
    site.write_text(yaml.safe_dump(cfg), encoding="utf-8")
    proc = run_snakemake(site, tmp_path / "results", extra=["-n"], check=False)
    assert proc.returncode != 0
    assert "change.evaluation.dem2_truth: null means the twin's own truth" in proc.stdout + proc.stderr
    cfg["change"]["evaluation"]["dem2_truth"] = "x.tif"
    cfg["change"]["epochs"] = None
    site.write_text(yaml.safe_dump(cfg), encoding="utf-8")
    proc = run_snakemake(site, tmp_path / "results", extra=["-n"], check=False)
    assert proc.returncode != 0
    assert "change.epochs: null (the twin's two surveys) needs a twin site" in proc.stdout + proc.stderr
