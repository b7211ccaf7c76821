"""benchmarks/obia_quantum_rebin.py: both maps made and scored on a small site, the stage's re-binning restored."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pandas as pd

from kitegully.io.raster import write_raster
from kitegully.obia import threshold

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "benchmarks"))
sys.path.insert(0, str(REPO / "tests"))

import obia_quantum_rebin as qr  # noqa: E402
from obia.test_kite import _site  # noqa: E402


def test_both_maps_are_scored_and_the_stage_rebinning_is_restored(tmp_path):
    grid, rgb, dsm, truth = _site()
    (tmp_path / "dense").mkdir()
    (tmp_path / "twin" / "truth").mkdir(parents=True)
    write_raster(tmp_path / "dense" / "orthophoto.tif", rgb, grid, nodata=None)
    write_raster(tmp_path / "dense" / "dsm.tif", dsm, grid)
    # land cover codes of the default site's classes: 1 bare_eroded, 3 grass
    write_raster(tmp_path / "twin" / "truth" / "landcover.tif", np.where(truth == 1, 1, 3).astype(np.uint8), grid, nodata=255)
    pd.DataFrame({"code": [1, 2, 3, 4, 5, 6, 7, 8, 9],
                  "name": ["bare_eroded", "ploughed", "grass", "shrub", "tree", "track", "building", "water", "gully"]}
                 ).to_csv(tmp_path / "twin" / "truth" / "landcover_classes.csv", index=False)
    original = threshold.central_histogram
    site = REPO / "config" / "sites" / "kamech_twin.yaml"
    rows = [qr.run(tmp_path, site, 128, None), qr.run(tmp_path, site, 128, 0.004)]
    assert threshold.central_histogram is original
    assert [r["re-binning"] for r in rows] == ["as the stage", "bins >= 0.004"]
    for r in rows:  # grass and soil are far apart in ExG: both rules map the patches
        assert r["valley"] is not None and r["OA_pct"] > 95.0
