"""The peat valley as a DEM twin site (issue 16): the twin_dem rule feeds the polygons stage, no photographs."""

from __future__ import annotations

import re

from snakemake_utils import REPO, run_snakemake


def test_dry_run_builds_the_dtm_then_the_polygons_and_their_evaluation(tmp_path):
    proc = run_snakemake(REPO / "config" / "sites" / "peat_valley.yaml", tmp_path / "results", extra=["-n"])
    jobs = dict(re.findall(r"^(\w+)\s+(\d+)$", proc.stdout, flags=re.M))
    counts = {k: int(v) for k, v in jobs.items() if k != "total"}
    for rule in ("twin_dem", "polygons_map", "polygons_figure", "polygons_table1", "polygons_evaluate"):
        assert counts.pop(rule) == 1
    # nothing photographic: the rest is the target rule and the report's QGIS project
    assert set(counts) <= {"all", "report_qgis"}
    # the stage reads the DEM twin's observed DTM inside the run's own results folder
    assert str(tmp_path / "results" / "peat_valley" / "twin" / "observed" / "dtm.tif") in proc.stdout
