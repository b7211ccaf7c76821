"""The polygons rules on the tiny twin, with a DEM file as input (a DEM site: no photographs).

The twin's DTM stands in for a TLS-like DEM given in ``polygons.dem_file``; this exercises
the four rules, their products and the twin evaluation without the slow dense chain.
"""

from __future__ import annotations

import geopandas as gpd
import pandas as pd
import pytest
import yaml

from snakemake_utils import REPO, run_snakemake


@pytest.mark.slow
def test_tiny_twin_polygons_on_a_dem_file(tmp_path):
    results = tmp_path / "results"
    site = results / "tiny_twin"
    cfg = yaml.safe_load((REPO / "config" / "sites" / "tiny_twin.yaml").read_text(encoding="utf-8"))
    cfg["polygons"]["dem_file"] = str(site / "twin" / "truth" / "dtm.tif")
    site_file = tmp_path / "tiny_dem_site.yaml"
    site_file.write_text(yaml.safe_dump(cfg), encoding="utf-8")
    out = site / "polygons"
    run_snakemake(site_file, results, [str(out / n) for n in ("gully_polygons.png", "table1.csv", "polygon_scores.csv")], cores=1)
    for t in ("0.5", "1", "1.5", "2", "2.5", "3"):
        g = gpd.read_file(out / f"gully_polygons_t{t}.gpkg")
        assert g.crs.to_string() == "EPSG:32632" and {"polygon_id", "area_m2"} <= set(g.columns)
    sec = gpd.read_file(out / "cross_sections.gpkg")
    assert {"width_m", "depth_m", "area_m2"} <= set(sec.columns) and len(sec) > 0
    morph = pd.read_csv(out / "morphometry.csv")
    assert {"length_m", "mean_width_m", "max_depth_m", "volume_m3"} <= set(morph.columns)
    t1 = pd.read_csv(out / "table1.csv").set_index("statistic")
    assert t1.loc["sets", "auto"] == 6 and t1.loc["sets", "manual"] == 9
    scores = pd.read_csv(out / "polygon_scores.csv").set_index("kind")
    assert 0 < scores.loc["all", "iou"] <= 1
    errs = pd.read_csv(out / "morphometry_errors.csv")
    assert list(errs["quantity"][:3]) == ["width (m)", "depth (m)", "area (m2)"]
    for f in ("gully_polygons.png", "manual_comparison.png", "polygons_summary.csv", "medial_axes.gpkg"):
        assert (out / f).exists(), f
