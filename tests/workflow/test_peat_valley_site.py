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


def test_tiled_dry_run_measures_the_polygons_in_tile_jobs(tmp_path):
    """With a tiling section (issue 21) step 6 runs as one job per tile plus one merge."""
    extra = tmp_path / "tiled.yaml"
    extra.write_text("tiling:\n  tile_m: 200.0\n  extent: {width_m: 600.0, height_m: 350.0}\n", encoding="utf-8")
    proc = run_snakemake(REPO / "config" / "sites" / "peat_valley.yaml", tmp_path / "results",
                         extra=["-n", "--configfile", str(REPO / "config" / "sites" / "peat_valley.yaml"), str(extra)])
    counts = {k: int(v) for k, v in re.findall(r"^(\w+)\s+(\d+)$", proc.stdout, flags=re.M)}
    assert counts["polygons_map"] == 1 and counts["polygons_morph_tile"] == 2 * 3 and counts["polygons_morph_merge"] == 1
    assert str(tmp_path / "results" / "peat_valley" / "polygons" / "tiles" / "morph" / "r001_c002.pkl") in proc.stdout
