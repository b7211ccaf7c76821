"""The low-cost site's workflow: a dry run plans the six lowcost rules and nothing else."""

from __future__ import annotations

from snakemake_utils import REPO, run_snakemake


def test_lowcost_site_dry_run_plans_its_rules_only(tmp_path):
    proc = run_snakemake(REPO / "config/sites/lowcost_twin.yaml", tmp_path / "results", extra=["--dry-run"])
    out = proc.stdout + proc.stderr
    for rule in ("lowcost_twin", "lowcost_spectral", "lowcost_survey", "lowcost_rtk_bundle", "lowcost_bare_soil",
                 "lowcost_evaluate"):
        assert f"rule {rule}:" in out or f"localrule {rule}:" in out
    for other in ("twin_generate", "sfm_reconstruct", "dense_match", "gully_map"):
        assert other not in out
    assert "nir_orthomosaic.tif" in out and "georef_residuals.csv" in out
    assert "bare_soil_ndvi.tif" in out and "bare_soil_obia.csv" in out and "dsm_truth.csv" in out


def test_default_site_has_no_lowcost_rule(tmp_path):
    proc = run_snakemake(REPO / "config/sites/tiny_twin.yaml", tmp_path / "results", extra=["--dry-run"])
    assert "lowcost_" not in proc.stdout + proc.stderr
