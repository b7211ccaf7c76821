"""Kite-scale OBIA rules on the tiny_twin site with fabricated dense + twin outputs.

The dense stage's orthophoto/DSM and the twin's land-cover truth are written by the test
(the synthetic site of test_obia_kite plus a land-cover raster on a coarser grid), so
only ``obia_kite_scale`` and ``obia_kite_accuracy`` run (``--allowed-rules``).
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from PIL import Image

from kitegully.io.raster import GridSpec, read_raster, write_raster
from snakemake_utils import REPO, run_snakemake
from obia.test_kite import CRS, _site

SITE = REPO / "config" / "sites" / "tiny_twin.yaml"
CLASSES = ["bare_eroded", "ploughed", "grass", "shrub", "tree", "track", "building", "water", "gully"]


@pytest.fixture(scope="module")
def kite_run(tmp_path_factory):
    results = tmp_path_factory.mktemp("obia_kite_results")
    root = results / "tiny_twin"
    grid, rgb, dsm, truth = _site(seed=11)
    write_raster(root / "dense" / "orthophoto.tif", rgb, grid, nodata=None)
    write_raster(root / "dense" / "dsm.tif", dsm, grid)
    # land cover on a 0.2 m grid (4 x the orthophoto cell): bare_eroded (1) / grass (3)
    lc_grid = GridSpec(grid.x0, grid.y0, 0.2, grid.width // 4, grid.height // 4, CRS)
    lc = np.where(truth.reshape(lc_grid.height, 4, lc_grid.width, 4).mean(axis=(1, 3)) >= 0.5, 1, 3).astype(np.uint8)
    write_raster(root / "twin" / "truth" / "landcover.tif", lc, lc_grid, nodata=255)
    pd.DataFrame({"code": np.arange(1, 10), "name": CLASSES}).to_csv(root / "twin" / "truth" / "landcover_classes.csv", index=False)
    out = root / "obia" / "kite"
    targets = [str(out / n) for n in ("bare_soil.tif", "bare_soil.gpkg", "bare_soil_map.png", "accuracy.csv", "landcover_agreement.csv")]
    run_snakemake(SITE, results, targets, extra=["--allowed-rules", "obia_kite_scale", "obia_kite_accuracy", "--printshellcmds"], cores=2)
    return out, grid, truth, lc


def test_kite_map_products(kite_run):
    out, grid, truth, _ = kite_run
    classes, g = read_raster(out / "bare_soil.tif")
    assert g == grid and classes.dtype == np.uint8
    assert set(np.unique(classes)) <= {0, 1, 255}
    # pure colours: only cells within a seed band width of a patch edge can be wrong
    assert np.mean(classes == truth) > 0.99
    with Image.open(out / "bare_soil_map.png") as im:
        assert im.size[0] > 2000  # 15 in at 300 dpi


def test_kite_accuracy_against_landcover(kite_run):
    out, grid, truth, lc = kite_run
    acc = pd.read_csv(out / "accuracy.csv")
    assert list(acc.columns) == ["scene", "class", "users_accuracy", "producers_accuracy", "overall_accuracy"]
    assert set(acc["class"]) == {"vegetated", "bare"}
    # the 0.2 m land cover misplaces patch edges by up to half a coarse cell; that alone
    # caps the agreement at the truth's own agreement with the coarse land cover, and the
    # map may lose at most its own error rate (< 1 %, test_kite_map_products) on top
    lc_fine = np.repeat(np.repeat(lc, 4, axis=0), 4, axis=1) == 1
    ceiling = 100.0 * np.mean(lc_fine == (truth == 1))
    assert acc["overall_accuracy"].iloc[0] > ceiling - 1.0
    per = pd.read_csv(out / "landcover_agreement.csv").set_index("landcover_class")
    assert set(per.index) == {"bare_eroded", "grass"}
    truth_in_bare = 100.0 * np.mean(truth[lc_fine] == 1)
    truth_in_grass = 100.0 * np.mean(truth[~lc_fine] == 1)
    n_bare, n_grass = lc_fine.sum(), (~lc_fine).sum()
    map_err = 0.01 * truth.size  # cells the map may get wrong
    assert per.loc["bare_eroded", "mapped_bare_pct"] > truth_in_bare - 100.0 * map_err / n_bare
    assert per.loc["grass", "mapped_bare_pct"] < truth_in_grass + 100.0 * map_err / n_grass
    assert per.loc["bare_eroded", "area_m2"] == pytest.approx(np.sum(lc == 1) * 0.04, rel=1e-6)
