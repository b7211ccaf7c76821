"""benchmarks/obia_descent.py: the four thresholds of one histogram, each mapped and scored, on a small site."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pandas as pd

from kitegully.io.raster import write_raster
from kitegully.obia.threshold import IndexHistogram

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "benchmarks"))
sys.path.insert(0, str(REPO / "tests"))

import obia_descent  # noqa: E402
from obia.test_kite import _site  # noqa: E402


def test_four_thresholds_are_scored_and_the_histogram_saved(tmp_path):
    grid, rgb, dsm, truth = _site()
    (tmp_path / "site" / "dense").mkdir(parents=True)
    (tmp_path / "site" / "twin" / "truth").mkdir(parents=True)
    res = tmp_path / "site"
    write_raster(res / "dense" / "orthophoto.tif", rgb, grid, nodata=None)
    write_raster(res / "dense" / "dsm.tif", dsm, grid)
    # land cover codes of the default site's classes: 1 bare_eroded, 3 grass
    write_raster(res / "twin" / "truth" / "landcover.tif", np.where(truth == 1, 1, 3).astype(np.uint8), grid, nodata=255)
    pd.DataFrame({"code": [1, 2, 3, 4, 5, 6, 7, 8, 9],
                  "name": ["bare_eroded", "ploughed", "grass", "shrub", "tree", "track", "building", "water", "gully"]}
                 ).to_csv(res / "twin" / "truth" / "landcover_classes.csv", index=False)
    out = tmp_path / "table"
    assert obia_descent.main(["--results", str(res), "--site", str(REPO / "config" / "sites" / "kamech_twin.yaml"),
                              "--tile-cells", "128", "--out", str(out), "--save-histogram", str(tmp_path / "h")]) == 0
    table = pd.read_csv(out.with_suffix(".csv"))
    assert list(table["threshold"]) == ["paper valley", "lowest mode, no tests", "floor only", "stage"]
    # grass and soil are far apart in ExG: every threshold maps the patches
    assert (table["OA_pct"] > 95.0).all()
    assert table["index_step"].iloc[0] != table["index_step"].iloc[0]  # NaN: the paper's valley has no descent
    assert 0.004 < table["index_step"].iloc[3] < 0.008  # 2 / DN sum of the soil (330)
    h = IndexHistogram.load(tmp_path / "h" / "site_histogram.npz")
    assert h.quantised and h.counts.sum() == truth.size
