"""The change stage through Snakemake on a small DEM site (two synthetic epoch GeoTIFFs).

Epoch 2 is epoch 1's terrain with a known pit and mound, shifted by (0.5, −0.3) m and raised
by 0.1 m, both with 0.03 m noise; the site states the accuracies (one SD, one checkpoint
file), a gully mask and a digitised head, and names the true surfaces for the evaluation.
"""

from __future__ import annotations

import copy

import geopandas as gpd
import numpy as np
import pandas as pd
import pytest
import yaml
from shapely.geometry import Point, box

from change.change_synth import CRS, bump, grid, noise, terrain, write, xy
from kitegully.config import load_yaml
from snakemake_utils import REPO, run_snakemake


def _site(tmp_path):
    g = grid(240, cell=0.5)
    X, Y = xy(g)
    z = terrain(X, Y)
    change = bump(g, 30.0, 30.0, 8.0, -0.8) + bump(g, 80.0, 70.0, 6.0, 0.5)
    dx, dy = 0.5, -0.3
    z2_true = z + change
    z2_obs = terrain(X - dx, Y - dy) + (bump(g, 30.0 + dx, 30.0 - dy, 8.0, -0.8) + bump(g, 80.0 + dx, 70.0 - dy, 6.0, 0.5)) + 0.1
    d = tmp_path / "inputs"
    d.mkdir()
    files = dict(
        dem1=write(d / "dem1.tif", z + noise(g, 0.03, "w1"), g), dem2=write(d / "dem2.tif", z2_obs + noise(g, 0.03, "w2"), g),
        truth1=write(d / "truth1.tif", z, g), truth2=write(d / "truth2.tif", z2_true, g))
    rng = np.random.default_rng(5)
    r, c = rng.integers(5, 235, 200), rng.integers(5, 235, 200)
    pd.DataFrame(dict(id=range(200), x=X[r, c], y=Y[r, c], z=z[r, c])).to_csv(d / "cp1.csv", index=False)
    gpd.GeoDataFrame({"gully_id": [1, 2]}, geometry=[box(g.x0 + 20, g.y0 - 40, g.x0 + 40, g.y0 - 20),
                                                     box(g.x0 + 72, g.y0 - 78, g.x0 + 88, g.y0 - 62)], crs=CRS).to_file(d / "gully.gpkg")
    gpd.GeoDataFrame({"head_id": [1]}, geometry=[Point(g.x0 + 60, g.y0 - 60)], crs=CRS).to_file(d / "heads.gpkg")
    ch = copy.deepcopy(load_yaml(REPO / "config/sites/kamech_dem_change.yaml")["change"])
    ch["epochs"] = [dict(name="e1", dem=files["dem1"], nodata=None, accuracy=dict(checkpoints=str(d / "cp1.csv"))),
                    dict(name="e2", dem=files["dem2"], nodata=None, accuracy=dict(sd_m=0.03))]
    ch["masks"] = [dict(name="gully", file=str(d / "gully.gpkg"), kind="vector", by="gully_id", unstable=True)]
    ch["heads_file"] = str(d / "heads.gpkg")
    ch["sections_file"] = None
    ch["budget"]["variogram_max_lag_m"] = 40.0
    ch["evaluation"].update(dem1_truth=files["truth1"], dem2_truth=files["truth2"], heads1_truth=None, heads2_truth=None,
                           polygons1_truth=None, polygons2_truth=None)
    site = dict(site=dict(name="dem_site", kind="real", crs=CRS), seed=1, change=ch)
    path = tmp_path / "dem_site.yaml"
    path.write_text(yaml.safe_dump(site, sort_keys=False))
    return path, g, change


@pytest.mark.slow
def test_dem_site_change_stage(tmp_path):
    site_file, g, change = _site(tmp_path)
    results = tmp_path / "results"
    out = results / "dem_site" / "change"
    run_snakemake(site_file, results, [str(out / "evaluation_summary.csv")])
    for name in ("dod.tif", "sigma_dod.tif", "dod_thresholded_probabilistic.tif", "dod_thresholded_coherence.tif",
                 "dod_map.png", "budget_bars.png", "dod_histogram.png", "variogram.png", "headcut_retreat.csv",
                 "detection.csv", "budget_vs_truth.csv"):
        assert (out / name).exists(), name
    co = pd.read_csv(out / "coregistration.csv").set_index("quantity")["value"]
    assert co["dx"] == pytest.approx(0.5, abs=0.05) and co["dy"] == pytest.approx(-0.3, abs=0.05)
    assert co["dz_at_centre"] == pytest.approx(0.1, abs=0.01)
    b = pd.read_csv(out / "budget_vs_truth.csv").set_index(["mask", "method"])
    assert list(b.columns[:6]) == ["erosion_m3", "deposition_m3", "net_m3", "net_sd_m3", "net_sd_independent_m3", "net_sd_correlated_m3"]
    for mask in ("gully:1", "gully:2"):
        row = b.loc[(mask, "raw")]
        assert abs(row["net_m3"] - row["true_net_m3"]) <= 2 * row["net_sd_m3"], mask
    det = pd.read_csv(out / "detection.csv").set_index("method")
    assert det.loc["probabilistic", "false_rate"] < 0.06 and det.loc["probabilistic", "detection_rate"] > 0.9
