"""End to end on the tiny twin: … → georeferencing → dense matching → DEM validation.

Slow (renders, reconstructs and matches a 12-image strip). Asserts the products' format
and the issue-6 checkpoint targets in ground sampling distances of the flight (GSD, from
the flight summary): |mean| ≤ 0.5 GSD and SD ≤ 1.5 GSD on bare-ground checkpoints. The
coverage target (≥ 95 % of the area seen by ≥ 2 images) is the default twin's: the tiny
twin is one strip at 0.27 m GSD over low-contrast ploughed soil and a textureless lake,
so here only ≥ 85 % of the non-water cells seen by ≥ 2 images is asserted.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
import rasterio

from snakemake_utils import REPO, run_snakemake


@pytest.fixture(scope="module")
def tiny_dense(tmp_path_factory):
    """Results folder of the untiled tiny twin up to the checkpoint validation (run once)."""
    results = tmp_path_factory.mktemp("tiny_dense") / "results"
    site = results / "tiny_twin"
    run_snakemake(REPO / "config" / "sites" / "tiny_twin.yaml", results,
                  [str(site / "validate" / "checkpoint_summary.csv"), str(site / "validate" / "profile_stats.csv")],
                  cores=2)
    return results


@pytest.mark.slow
def test_tiny_twin_dense_and_validation(tiny_dense):
    site = tiny_dense / "tiny_twin"
    with rasterio.open(site / "dense" / "dsm.tif") as src:
        assert src.dtypes[0] == "float32" and np.isnan(src.nodata) and src.crs.to_string() == "EPSG:32632"
        assert src.block_shapes[0] == (256, 256) or min(src.width, src.height) < 256
        dsm = src.read(1)
        assert np.isfinite(dsm).any() and np.isnan(dsm).any()
    with rasterio.open(site / "dense" / "orthophoto.tif") as src:
        assert src.count >= 3 and src.dtypes[0] == "uint8" and src.nodata is None
        assert src.mask_flag_enums[0] == [rasterio.enums.MaskFlags.per_dataset]  # mask band, not 0 as nodata
        seen = src.dataset_mask() > 0
        assert seen.any() and np.all(src.read()[:, ~seen] == 0)
    from rio_cogeo.cogeo import cog_validate
    for name in ("dsm.tif", "correlation.tif", "orthophoto.tif"):
        assert cog_validate(site / "dense" / name, quiet=True)[0], name
    for name in ("correlation.tif", "hillshade.png", "openness.png", "dense_summary.csv"):
        assert (site / "dense" / name).exists(), name
    gsd = pd.read_csv(site / "flight" / "flight_summary.csv").set_index("quantity").loc["gsd_median", "value"]
    summ = pd.read_csv(site / "validate" / "checkpoint_summary.csv")
    assert list(summ.columns) == ["statistic", "value_m"]
    assert list(summ["statistic"]) == ["mean", "median", "sd", "rmse", "nmad", "p05", "p95", "n"]
    groups = pd.read_csv(site / "validate" / "checkpoint_summary_by_group.csv").set_index("statistic")
    assert groups.loc["n", "bare_m"] >= 30
    assert abs(groups.loc["mean", "bare_m"]) <= 0.5 * gsd
    assert groups.loc["sd", "bare_m"] <= 1.5 * gsd
    lc = pd.read_csv(site / "validate" / "dsm_error_by_landcover.csv").set_index("landcover")
    land = lc.drop(index=["all", "water"], errors="ignore")
    valid_land = float((land["area_pct"] * land["valid_pct"]).sum() / land["area_pct"].sum())
    assert valid_land >= 85.0, lc
    prof = pd.read_csv(site / "validate" / "profile_stats.csv")
    assert list(prof["profile"]) == ["whole", "no_vegetation"]
    errs = pd.read_csv(site / "validate" / "checkpoint_errors.csv")
    assert {"id", "x_m", "y_m", "z_ref_m", "z_model_m", "error_m"} <= set(errs.columns)


@pytest.mark.slow
def test_tiny_twin_tiled_dense_equals_untiled(tiny_dense, tmp_path):
    """Issue 21: the tiny twin as a tiled site (2 x 2 dense tile jobs + merge) gives the untiled DSM and checkpoints."""
    import shutil

    results = tmp_path / "results"
    shutil.copytree(tiny_dense, results, symlinks=True)  # keeps mtimes: only dense and validate rerun
    site = results / "tiny_twin"
    for stage in ("dense", "validate"):
        shutil.rmtree(site / stage)
    proc = run_snakemake(REPO / "config" / "sites" / "tiny_twin.yaml", results,
                         [str(site / "validate" / "checkpoint_summary.csv"), str(site / "dense" / "dense_summary.csv")],
                         extra=["--configfile", str(REPO / "config" / "sites" / "tiny_twin.yaml"),
                                str(REPO / "tests" / "workflow" / "tiny_twin_tiled.yaml"), "--rerun-triggers=mtime"],
                         cores=2)
    assert proc.stdout.count("rule dense_tile:") + proc.stderr.count("rule dense_tile:") == 4
    assert "rule dense_match:" not in proc.stdout + proc.stderr
    ref = tiny_dense / "tiny_twin"
    for name in ("dsm.tif", "correlation.tif"):
        with rasterio.open(ref / "dense" / name) as a, rasterio.open(site / "dense" / name) as b:
            x, y = a.read(1), b.read(1)
            assert a.transform == b.transform
        assert np.array_equal(np.isfinite(x), np.isfinite(y)), name
        assert np.nanmax(np.abs(x - y)) <= 1e-4, name  # measured: 0 (bit for bit)
    a = pd.read_csv(ref / "validate" / "checkpoint_summary.csv").set_index("statistic")["value_m"]
    b = pd.read_csv(site / "validate" / "checkpoint_summary.csv").set_index("statistic")["value_m"]
    assert np.allclose(a, b, atol=1e-3, rtol=0), pd.concat([a, b], axis=1)
    summ = pd.read_csv(site / "dense" / "dense_summary.csv").set_index("quantity")["value"]
    assert summ["tile_jobs"] == 4
    # the orthophoto as 2 x 2 ortho_tile jobs equals the untiled rendering of the same DSM with the same
    # parameters (the tiled config's 128-cell blocks), bit for bit
    assert proc.stdout.count("rule ortho_tile:") + proc.stderr.count("rule ortho_tile:") == 4
    from kitegully.config import load_yaml
    from kitegully.dense import DenseParams
    from kitegully.dense.ortho import orthophoto
    from kitegully.dense.ortho_tiles import load_views
    from kitegully.io.raster import read_raster

    cfg = load_yaml(REPO / "config" / "sites" / "tiny_twin.yaml")["dense"]
    cfg["orthophoto"].update(load_yaml(REPO / "tests" / "workflow" / "tiny_twin_tiled.yaml")["dense"]["orthophoto"])
    p = DenseParams.from_config(cfg)
    views = load_views(site / "georef" / "model", site / "georef" / "transform.json", site / "sfm" / "work" / "images")
    dsm, grid = read_raster(site / "dense" / "dsm.tif")
    oc = p.orthophoto
    img, og, srcidx = orthophoto(views, dsm, grid, oc.upsample, oc.tile_cells, oc.overlap_m, oc.occlusion_tolerance_m,
                                 p.max_cached_images)
    with rasterio.open(site / "dense" / "orthophoto.tif") as src:
        assert src.count >= 3 and src.transform == og.transform
        assert np.array_equal(src.read(), img)  # measured: 0 of 640 000 cells differ
        assert np.array_equal(src.dataset_mask() > 0, srcidx >= 0)
    from rio_cogeo.cogeo import cog_validate
    assert cog_validate(site / "dense" / "orthophoto.tif", quiet=True)[0]
