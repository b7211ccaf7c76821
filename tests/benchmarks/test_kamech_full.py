"""benchmarks/kamech_full.py: the accuracy rows and the re-tabulation of a finished run."""

from __future__ import annotations

import os
import sys
from datetime import datetime
from pathlib import Path

import pandas as pd
import pytest

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "benchmarks"))

import kamech_full as kf  # noqa: E402


def _site(tmp_path: Path) -> Path:
    site = tmp_path / "site"
    (site / "polygons").mkdir(parents=True)
    (site / "change").mkdir()
    (site / "validate/epoch2").mkdir(parents=True)
    pd.DataFrame({"gully_id": [0, 1, 2, -1, -1], "kind": ["wadi", "gully", "gully", "all", "wide"],
                  "iou": [0.7, 0.2, 0.1, 0.4, 0.55]}).to_csv(site / "polygons/polygon_scores.csv", index=False)
    pd.DataFrame({"quantity": ["width (m)", "depth (m)", "volume, all sections vs all true gullies (m3)"],
                  "median_abs_error": [0.8, 0.2, float("nan")], "error_pct": [float("nan")] * 2 + [-6.3]}
                 ).to_csv(site / "polygons/morphometry_errors.csv", index=False)
    pd.DataFrame({"quantity": ["site_net_error_pct", "headcut median |error| (heads that retreated)"],
                  "value": [4.0, 0.63], "unit": ["%", "m"]}).to_csv(site / "change/evaluation_summary.csv", index=False)
    pd.DataFrame({"statistic": ["mean", "sd", "n"], "value_m": [-0.3, 0.25, 454]}
                 ).to_csv(site / "validate/epoch2/checkpoint_summary.csv", index=False)
    return site


def test_polygon_rows_carry_the_issues_metric_not_only_the_median(tmp_path):
    acc = kf.accuracies(_site(tmp_path))
    # the issue's IoU is over the cells of all gullies wider than 2 m, not a median of per-gully IoUs
    assert acc["polygon IoU, gullies wider than 2 m"] == pytest.approx(0.55)
    assert acc["polygon IoU (median over gullies)"] == pytest.approx(0.2)  # summary rows (id -1) left out
    assert acc["polygon width median abs error"] == pytest.approx(0.8)
    assert acc["polygon depth median abs error"] == pytest.approx(0.2)
    assert acc["polygon volume error"] == pytest.approx(-6.3)
    assert acc["headcut retreat median abs error"] == pytest.approx(0.63)
    assert acc["checkpoint SD, epoch 2"] == pytest.approx(0.25) and acc["checkpoint n, epoch 2"] == 454
    assert set(acc) <= set(kf.PAPER)  # every row has its paper value and target entry


def test_retabulation_keeps_the_timed_rows_only(tmp_path):
    table = tmp_path / "benchmark.csv"
    assert kf.timed_rows(table) == []
    pd.DataFrame({"extent": "x", "kind": ["run", "run", "scaling", "rule", "accuracy"],
                  "item": ["total wall (Snakemake, --cores 2)", "largest peak memory of any job",
                           "tiled stages speed-up 1 -> 2 cores", "twin wall", "checkpoint SD"],
                  "value": [7000.0, 5000.0, 1.6, 200.0, 0.1], "unit": ["s", "MB", "x", "s", "m"],
                  "paper": [None, None, None, None, 0.22], "target": ["<= 10800 (3 h)", "<= 8000", None, None, None]}
                 ).to_csv(table, index=False)
    rows = kf.timed_rows(table)
    assert [r[1] for r in rows] == ["total wall (Snakemake, --cores 2)", "tiled stages speed-up 1 -> 2 cores"]
    assert rows[0][2] == 7000.0 and rows[0][5] == "<= 10800 (3 h)" and rows[1][5] is None


def test_wall_time_from_the_snakemake_log(tmp_path):
    log = tmp_path / "benchmark_run.log"
    assert kf.wall_from_log(log) is None
    # no header: the span of the job timestamps
    log.write_text("Building DAG of jobs...\n[Tue Dec  1 23:54:43 2026]\nlocalrule twin:\n"
                   "    jobid: 3\n[Wed Dec  2 01:04:45 2026]\nFinished jobid: 3\n")
    assert kf.wall_from_log(log) == 70 * 60 + 2
    log.write_text("[Tue Dec  1 23:54:43 2026]\n")
    assert kf.wall_from_log(log) is None
    # Snakemake's header: from its start to the log's last write
    log.write_text("SNAKEMAKE\n  Date: 2026-12-01 23:54:39\n[Tue Dec  1 23:54:43 2026]\n")
    end = datetime(2026, 12, 2, 1, 21, 14).timestamp()
    os.utime(log, (end, end))
    assert kf.wall_from_log(log) == 86 * 60 + 35


def test_a_resumed_run_keeps_the_interrupted_runs_log(tmp_path):
    assert kf.run_log(tmp_path).name == "benchmark_run.log"
    (tmp_path / "benchmark_run.log").write_text("run 1")
    assert kf.run_log(tmp_path).name == "benchmark_run2.log"
    (tmp_path / "benchmark_run2.log").write_text("run 2")
    assert kf.run_log(tmp_path).name == "benchmark_run3.log"


def test_scaling_reruns_a_chosen_subset_of_tile_rules_until_their_merges():
    assert kf.scaling_targets(None) == (list(kf.TILE_RULES), list(kf.MERGE_RULES))
    tiles, merges = kf.scaling_targets(["gully_fill_tile", "gully_depth_tile"])
    assert tiles == ["gully_depth_tile", "gully_fill_tile"] and merges == ["gully_depth_mosaic", "gully_fill_mosaic"]
    assert "gully_depth_tile + gully_fill_tile" in kf.scaling_label(tiles, 1)
    assert "change" in kf.scaling_label(list(kf.TILE_RULES), 2) and kf.scaling_label(tiles, 2).endswith("--cores 2")
    with pytest.raises(SystemExit, match="dense_tile is not a tile rule"):
        kf.scaling_targets(["dense_tile"])


def test_stage_costs_sum_the_jobs_of_each_stage():
    costs = pd.DataFrame({"job": ["dense/dense_tile_r000_c000", "dense/epoch2/dense_tile_r000_c000", "twin/epoch1"],
                          "wall_s": [100.0, 120.0, 250.0], "cpu_s": [90.0, 110.0, 240.0], "max_rss_mb": [900.0, 950.0, 1000.0]})
    st = kf.stage_costs(costs)
    assert st["stage"].tolist() == ["twin", "dense"]
    dense = st.set_index("stage").loc["dense"]
    assert dense["jobs"] == 2 and dense["wall_s"] == 220.0 and dense["cpu_s"] == 200.0 and dense["max_rss_mb"] == 950.0
    assert kf.stage_costs(kf.rule_costs(Path("/nonexistent"))).empty


def test_log_peaks_read_each_rules_high_water_mark(tmp_path):
    site = tmp_path / "site"
    (site / "logs/gully").mkdir(parents=True)
    (site / "logs/change").mkdir()
    (site / "logs/gully/gully_map.log").write_text(
        "x INFO a: start\nx INFO kitegully: peak memory: 6100 MB resident (high-water mark); largest child process 0 MB\n")
    (site / "logs/change/evaluate.log").write_text(
        "x INFO kitegully: peak memory: 900 MB resident (high-water mark); largest child process 11300 MB\n")
    (site / "logs/change/failed.log").write_text("a.tif: no CRS\n")  # a failed job states no peak
    peaks = kf.log_peaks(site)
    assert peaks["job"].tolist() == ["change/evaluate", "gully/gully_map"]
    assert peaks["peak_mb"].tolist() == [11300.0, 6100.0]  # a child's peak counts as the job's


def test_a_run_below_the_gully_target_keeps_its_dsm_and_gully_tables(tmp_path):
    site = tmp_path / "site"
    (site / "dense").mkdir(parents=True)
    (site / "gully").mkdir()
    (site / "dense/dsm.tif").write_bytes(b"dsm")
    (site / "gully/network_validation.csv").write_text("category,percent\ngood_fit,79.5\n")
    assert kf.keep_below_target(site, {"gully good fit 5 m": 87.2}) is None
    assert not (site / "kept_below_target").exists()
    kept = kf.keep_below_target(site, {"gully good fit 5 m": 79.5})
    assert (kept / "dense/dsm.tif").read_bytes() == b"dsm"
    assert (kept / "gully/network_validation.csv").exists()
    assert not (kept / "dense/orthophoto.tif").exists()  # what is missing is skipped, not invented
    assert kf.keep_below_target(site, {}) is None  # no gully row: nothing to judge
