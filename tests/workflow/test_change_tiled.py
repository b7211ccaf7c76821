"""Issue 21: the change stage of a tiled DEM site as tile jobs equals the untiled stage.

The DEM site of tests/workflow/test_change.py (two synthetic epoch GeoTIFFs of 240 x 240
cells, shifted, raised, a pit and a mound, a gully mask, a head) with a ``tiling`` section of
2 x 2 tiles: change_plan, 4 change_stable_tile, change_coregister, 4 change_tile and
change_merge run, then change_evaluate on the merged products. The reference is the
untiled rule's library call (``detect_change``) with the same inputs and parameters (one
Snakemake run, not two, to keep the file short on the loaded 2-core machine).
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
import rasterio
import yaml

from kitegully.change.params import THRESHOLD_METHODS, ChangeParams
from kitegully.change.stage import detect_change
from snakemake_utils import run_snakemake
from workflow.test_change import _site

TABLES = {"coregistration": "coregistration.csv", "sigma": "sigma.csv", "thresholds": "thresholds.csv",
          "variogram": "variogram.csv", "budget": "budget.csv", "headcuts": "headcut_retreat.csv", "widening": "widening.csv"}
RASTERS = {"dod": "dod.tif", "sigma_dod": "sigma_dod.tif", "stable": "stable_ground.tif",
           **{f"thresholded_{m}": f"dod_thresholded_{m}.tif" for m in THRESHOLD_METHODS}}
FIGURES = {"dod_map": "dod_map.png", "budget_bars": "budget_bars.png", "histogram": "dod_histogram.png",
           "variogram_png": "variogram.png"}


@pytest.mark.slow
def test_tiled_dem_site_change_equals_untiled(tmp_path):
    site_file, g, _ = _site(tmp_path)
    cfg = yaml.safe_load(site_file.read_text())
    cfg["tiling"] = {"tile_m": 60.0, "extent": {"width_m": 120.0, "height_m": 120.0}}  # 2 x 2 tiles of 120 x 120 cells
    tiled_file = tmp_path / "dem_site_tiled.yaml"
    tiled_file.write_text(yaml.safe_dump(cfg, sort_keys=False))
    results = tmp_path / "results"
    out = results / "dem_site" / "change"
    proc = run_snakemake(tiled_file, results, [str(out / "evaluation_summary.csv")], cores=2)
    log = proc.stdout + proc.stderr
    assert log.count("rule change_tile:") == 4 and log.count("rule change_stable_tile:") == 4
    assert "rule change_detect:" not in log and "rule change_merge:" in log and "rule change_evaluate:" in log
    assert not list((out / "tiles").glob("*.npz"))  # temp() tile files removed

    ch = cfg["change"]
    ref = tmp_path / "ref"
    ref.mkdir()
    refs = {k: str(ref / v) for k, v in {**TABLES, **RASTERS, **FIGURES}.items()}
    methods = {k: ch[k] for k in ("coregistration", "thresholds", "budget", "headcuts", "quality", "widening") if k in ch}
    detect_change(ch["epochs"], ch["masks"], ch["heads_file"], ChangeParams.from_config(methods, seed=cfg["seed"]), refs,
                  site_crs=cfg["site"]["crs"], figure=ch["figure"], sections_path=ch.get("sections_file"))
    for k, name in RASTERS.items():
        with rasterio.open(refs[k]) as a, rasterio.open(out / name) as b:
            assert a.transform == b.transform
            assert np.array_equal(a.read(1), b.read(1), equal_nan=True), k  # measured: bit for bit
    for k, name in TABLES.items():
        a, b = pd.read_csv(refs[k]), pd.read_csv(out / name)
        if k == "budget":  # sums over tiles of per-tile partial sums: another summation order
            # (a clean-clone run measured 2e-12 relative, e.g. 255.13985633850 against 255.13985633900 m3)
            assert a[["mask", "method"]].equals(b[["mask", "method"]])
            np.testing.assert_allclose(b.iloc[:, 2:].to_numpy(float), a.iloc[:, 2:].to_numpy(float), rtol=1e-9, atol=1e-12)
        else:  # the co-registration is a least-squares fit through BLAS, whose summation order follows the
            # thread count (Snakemake sets it per job, the test process does not): the fit and the tables
            # computed from its residuals (sigma, ...) differ in the last bits between the two (clean-clone runs);
            # the variogram's mean lags (means of ~1e5 pair distances) once differed by ~1e-12 relative
            # (32.4081111573 m both ways to 12 digits, over rtol 1e-12): summation-order noise, so 1e-9
            pd.testing.assert_frame_equal(a, b, check_exact=False, rtol=1e-9, atol=1e-12, obj=k)
    co = pd.read_csv(out / "coregistration.csv").set_index("quantity")["value"]
    assert co["dx"] == pytest.approx(0.5, abs=0.05) and co["dy"] == pytest.approx(-0.3, abs=0.05)
    det = pd.read_csv(out / "detection.csv").set_index("method")
    assert det.loc["probabilistic", "detection_rate"] > 0.9
