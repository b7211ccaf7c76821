"""benchmarks/gsd_experiment.py: two runs' evaluation tables side by side."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "benchmarks"))

import gsd_experiment as gx  # noqa: E402


def _run(root: Path, depth_err: float, headcut: float, wall: float) -> Path:
    (root / "polygons").mkdir(parents=True)
    (root / "change").mkdir()
    (root / "benchmarks/dense").mkdir(parents=True)
    pd.DataFrame({"gully_id": [3, -1, -1], "kind": ["V", "all", "wide"], "iou": [0.5, 0.55, 0.62],
                  "precision": [0.9, 0.9, 0.91], "recall": [0.6, 0.6, 0.66]}).to_csv(root / "polygons/polygon_scores.csv", index=False)
    pd.DataFrame({"quantity": ["width (m)", "depth (m)", "area (m2)", "volume, all sections vs all true gullies (m3)"],
                  "median_abs_error": [0.8, abs(depth_err), 1.0, None], "median_error": [-0.3, depth_err, 0.9, None],
                  "error_pct": [None, None, None, -4.4]}).to_csv(root / "polygons/morphometry_errors.csv", index=False)
    pd.DataFrame({"shape": ["U", "U", "V"], "depth_error_m": [0.1, 0.3, -depth_err]}).to_csv(
        root / "polygons/morphometry_errors_sections.csv", index=False)
    pd.DataFrame({"quantity": ["site_net_error_pct", "headcut median |error| (heads that retreated)", "moritani MAE"],
                  "value": [7.9, headcut, 0.03], "unit": ["%", "m", "m"]}).to_csv(root / "change/evaluation_summary.csv", index=False)
    pd.DataFrame({"head_id": [1, 2, 3], "true_gully_id": [1, 2, 3], "true_retreat_m": [0.6, 0.0, 2.0],
                  "retreat_m": [1.2, 0.1, headcut], "error_m": [0.6, 0.1, headcut - 2.0]}).to_csv(
        root / "change/headcut_retreat_vs_truth.csv", index=False)
    pd.DataFrame({"s": [wall], "max_rss": [1600.0]}).to_csv(root / "benchmarks/dense/dense_match.tsv", sep="\t", index=False)
    return root


def test_tables_side_by_side_and_per_head(tmp_path):
    base = _run(tmp_path / "base", 0.17, 0.63, 112.0)
    fine = _run(tmp_path / "fine", 0.09, 0.31, 450.0)
    t = gx.compare(base, fine).set_index("quantity")
    assert t.loc["polygons: iou, gullies > 2 m", "base"] == pytest.approx(0.62)
    assert t.loc["polygons: depth median |error| (m)"].tolist() == pytest.approx([0.17, 0.09])
    assert t.loc["polygons: depth median error, V sections (m)"].tolist() == pytest.approx([-0.17, -0.09])
    assert t.loc["polygons: depth median |error|, U sections (m)", "base"] == pytest.approx(0.2)
    assert t.loc["change: headcut |error| median, retreated heads (m)"].tolist() == pytest.approx([0.63, 0.31])
    assert t.loc["cost: dense/dense_match wall (s)"].tolist() == pytest.approx([112.0, 450.0])
    assert "DSM epoch 1: checkpoint SD (m)" not in t.index          # no validate tables: no row, no error
    heads = gx.heads_table(base, fine)
    assert heads["head_id"].tolist() == [1, 3]                      # the stable head is not a retreated head
    assert heads.loc[1, "retreat_m_fine"] == pytest.approx(0.31)


def test_main_refuses_a_run_without_change_tables(tmp_path, capsys):
    base = _run(tmp_path / "base", 0.17, 0.63, 112.0)
    assert gx.main(["--base", str(base), "--fine", str(tmp_path / "missing"), "--out", str(tmp_path / "o")]) == 2
    assert "no change/evaluation_summary.csv" in capsys.readouterr().out
    fine = _run(tmp_path / "fine", 0.09, 0.31, 450.0)
    assert gx.main(["--base", str(base), "--fine", str(fine), "--out", str(tmp_path / "o")]) == 0
    assert (tmp_path / "o.csv").exists() and "Headcut retreat per head" in (tmp_path / "o.md").read_text()


def test_profile_sampling_is_bilinear_on_a_plane_and_nan_outside():
    from kitegully.io.raster import GridSpec

    grid = GridSpec(100.0, 200.0, 0.5, 20, 10, "EPSG:32632")
    cols, rows = np.meshgrid(np.arange(20), np.arange(10))
    x_c, y_c = grid.x0 + (cols + 0.5) * grid.cell, grid.y0 - (rows + 0.5) * grid.cell
    z = 0.3 * x_c - 0.1 * y_c                                        # a plane: bilinear sampling is exact
    x = np.array([101.1, 104.37, 108.9, 95.0])
    y = np.array([198.2, 196.01, 196.4, 198.0])
    got = gx.sample_bilinear(z, grid, x, y)                          # the library's sampler the figure uses
    assert got[:3] == pytest.approx(0.3 * x[:3] - 0.1 * y[:3], abs=1e-9)
    assert np.isnan(got[3])                                           # west of the grid
