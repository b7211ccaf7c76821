"""The low-cost site's workflow: a dry run plans the six lowcost rules and nothing else; the chain runs on a short strip."""

from __future__ import annotations

import json

import pandas as pd
import pytest
import yaml

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


@pytest.mark.slow
def test_lowcost_chain_runs_on_a_short_strip(tmp_path):
    """All six rules from nothing on half the site's strip with half-size photos (about 35 s on 2 idle cores, 32 photos).

    The bounds are sanity bounds far from the site's numbers (docs/stages/10_lowcost.md): they catch a
    broken rule or a product that no longer means what it says, not a change of accuracy.
    """
    cfg = yaml.safe_load((REPO / "config/sites/lowcost_twin.yaml").read_text(encoding="utf-8"))
    tw = cfg["lowcost"]["twin"]
    tw["length_m"] = 20.0
    tw["camera"].update(image_width_px=614, image_height_px=408)
    cfg["lowcost"]["spectral"]["draws"] = 2
    site_file = tmp_path / "lowcost_short.yaml"
    site_file.write_text(yaml.safe_dump(cfg), encoding="utf-8")
    results = tmp_path / "results"
    run_snakemake(site_file, results, cores=2)
    out = results / "lowcost_twin" / "lowcost"
    survey = json.loads((out / "survey.json").read_text())
    assert survey["n_registered_rgb"] > 0 and survey["n_registered_nir"] > 0
    assert survey["n_registered"] == survey["n_images"] and survey["targets_triangulated"] == 9
    res = json.loads((out / "evaluation.json").read_text())
    assert abs(res["dsm_median_error_m"]) < 0.1 and res["dsm_nmad_m"] < 0.1
    assert res["max_abs_ndvi_error"] < 0.05
    assert min(res["bare_soil_obia_overall_accuracy"].values()) > 0.9
    local = pd.read_csv(out / "georef_residuals.csv").query("scope == 'local'")["residual_m"]
    assert (local < 0.05).all()                                           # taped edges to a few cm at 4 cm pixels
    for name in ("dsm.tif", "ndvi.tif", "bare_soil_ndvi.tif", "bare_ground_indicators.csv", "matches_by_pair_type.csv",
                 "spectral_peaks.csv", "dsm_truth.csv", "rtk_bundle/gcp_residuals.csv"):
        assert (out / name).exists(), name
