"""`make closerange`'s mode: closerange_sfm is a checkpoint and the summary waits for its records (issue 20)."""

from __future__ import annotations

from snakemake_utils import REPO, run_snakemake


def test_record_mode_plans_every_scene_and_leaves_the_per_scene_obia_to_the_records(tmp_path):
    # the make target's --config (closerange.scenes: all, on_scene_failure: record) on the tiny twin's two scenes
    # (a second --config replaces the first: results_dir is repeated; `--` ends its list before the target)
    results = tmp_path / "results"
    proc = run_snakemake(REPO / "config/sites/tiny_twin.yaml", results, ["closerange_summary"],
                         extra=["--dry-run", "--config", f"results_dir={results}",
                                "closerange={scenes: all, on_scene_failure: record}", "--"])
    out = proc.stdout + proc.stderr
    assert str(results) in out
    assert out.count("checkpoint closerange_sfm:") == 2  # both scenes' SfM at once, before the DAG is updated
    assert "closerange/scenes/scene_01/closerange.json" in out and "closerange/scenes/scene_02/closerange.json" in out
    assert "<TBD>" in out  # the summary's per-scene OBIA inputs follow from the records
    assert "rule closerange_classify:" not in out and "rule closerange_evaluate:" not in out
    assert "rule closerange_summary:" in out
