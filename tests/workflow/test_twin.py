"""The twin rules on the tiny_twin site: site.json, both epochs and the figures."""

from __future__ import annotations

from pathlib import Path

import pytest

from snakemake_utils import REPO, run_snakemake


@pytest.mark.slow
def test_workflow_tiny_twin(tmp_path):
    res = tmp_path / "results"
    base = res / "tiny_twin" / "twin"
    targets = [str(base / "site.json"), str(base / "figures/twin_site_overview.png"), str(base / "epoch2/truth/dtm.tif")]
    run_snakemake(REPO / "config/sites/tiny_twin.yaml", res, targets, cores=2)
    for t in targets:
        assert Path(t).is_file()
    assert (res / "tiny_twin/logs/twin/epoch1.log").is_file()
