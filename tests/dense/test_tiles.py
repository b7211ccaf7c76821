"""Dense DSM as tile jobs (issue 21): windows of whole matching blocks; tiled = untiled; merge."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
import rasterio

import dense_synthetic as ds
from conftest import REPO
from kitegully import InputError
from kitegully.config import load_yaml
from kitegully.dense import DenseParams
from kitegully.dense.matching import MatchParams
from kitegully.dense.surface import dense_surface
from kitegully.dense.tiles import dense_tiles, match_tile_window, matching_block, merge_dense_tiles, save_dense_tile
from kitegully.io.raster import GridSpec
from kitegully.seeds import rng_for
from kitegully.terrain.tiling import TilingParams

GRID = GridSpec(-4.8, 4.8, 0.1, 96, 88, "EPSG:32632")
MATCH = MatchParams(levels=4, window_half_cells=2, z_step_cells=0.5, refine_radius_steps=3, p1=0.02, p2=0.12,
                    sgm_directions=8, min_correlation=0.5)


def _params(**kw) -> DenseParams:
    base = DenseParams.from_config(load_yaml(REPO / "config/sites/tiny_twin.yaml")["dense"])
    return replace(base, cell_m=0.1, matching=MATCH, **kw)


def test_windows_are_whole_blocks_that_partition_the_grid():
    p = _params(tile_cells=250, overlap_cells=10)  # rounded up to multiples of 2**(levels-1) = 8
    assert matching_block(p) == (256, 16)
    tiling = TilingParams(tile_m=500.0, width_m=2120.0, height_m=1500.0)  # kamech_full: 5 x 3 tiles
    shape = (7500, 10600)
    tiles = dense_tiles(shape, p, tiling)
    assert [t.name for t in tiles] == tiling.names() and len(tiles) == 15
    cover = np.zeros(shape, np.int8)
    for t in tiles:
        assert t.r0 % 256 == 0 and t.c0 % 256 == 0
        cover[t.r0:t.r0 + t.h, t.c0:t.c0 + t.w] += 1
    assert (cover == 1).all()


def test_more_tiles_than_blocks_is_named():
    with pytest.raises(InputError, match=r"tiling.tile_m: 10 m gives 20 x 20 dense tiles but the DSM has only 2 x 2"):
        dense_tiles((400, 400), _params(tile_cells=256), TilingParams(tile_m=10.0, width_m=200.0, height_m=200.0))


@pytest.fixture(scope="module")
def slope_block():
    return ds.block(ds.slope(), rng_for(11, "test_dense_tiles", "slope"))


@pytest.fixture(scope="module")
def tiled(slope_block):
    """The synthetic slope matched whole and as 2 x 2 tile windows (3 x 3 blocks of 32 cells)."""
    views, imgs, _ = slope_block
    p = _params(tile_cells=32, overlap_cells=16)
    whole = dense_surface(views, GRID, MATCH, p.tile_cells, p.overlap_cells, arrays=imgs)
    tiles = dense_tiles(GRID.shape, p, TilingParams(tile_m=5.0, width_m=9.6, height_m=8.8))
    return p, whole, [(t, match_tile_window(views, GRID, t, p, arrays=imgs)) for t in tiles]


def test_tiled_dsm_equals_untiled_and_merges(tiled, tmp_path):
    p, whole, parts = tiled
    # 3 x 3 blocks of 32 cells split 2 x 2: windows of 1 and 2 blocks (the last clipped to the grid)
    assert [(t.h, t.w) for t, _ in parts] == [(32, 32), (32, 64), (56, 32), (56, 64)]
    files = []
    for t, res in parts:
        sl = (slice(t.r0, t.r0 + t.h), slice(t.c0, t.c0 + t.w))
        assert np.array_equal(np.isfinite(res.dsm), np.isfinite(whole.dsm[sl])), t.name
        assert np.nanmax(np.abs(res.dsm - whole.dsm[sl])) <= 1e-4, t.name
        assert np.array_equal(res.nseen, whole.nseen[sl])
        files.append(save_dense_tile(tmp_path / f"{t.name}.npz", res, t, GRID, p) and tmp_path / f"{t.name}.npz")
    out = {"dsm": tmp_path / "dsm.tif", "correlation": tmp_path / "correlation.tif", "stats": tmp_path / "stats.json"}
    stats = merge_dense_tiles(files[::-1], p, out)  # order of the inputs does not matter
    with rasterio.open(out["dsm"]) as src:
        dsm = src.read(1)
        assert src.transform == GRID.transform and np.isnan(src.nodata)
    assert np.array_equal(np.isfinite(dsm), np.isfinite(whole.dsm)) and np.nanmax(np.abs(dsm - whole.dsm)) <= 1e-4
    with rasterio.open(out["correlation"]) as src:
        assert np.nanmax(np.abs(src.read(1) - whole.ncc)) <= 1e-4
    assert stats["coverage_of_seen_pct"] == pytest.approx(100 * whole.coverage())
    assert stats["valid_pct"] == pytest.approx(100 * np.isfinite(whole.dsm).mean())
    assert stats["median_ncc"] == pytest.approx(float(np.nanmedian(whole.ncc)), abs=1e-4)
    assert stats["tiles"] == 9 and stats["tile_jobs"] == 4
    assert json.loads(out["stats"].read_text())["tile_jobs"] == 4
    assert not list(tmp_path.glob("*.raw.npy"))  # the disk-backed mosaic is removed


def test_merge_refuses_an_incomplete_set(tiled, tmp_path):
    p, _, parts = tiled
    t, res = parts[0]
    save_dense_tile(tmp_path / "a.npz", res, t, GRID, p)
    out = {"dsm": tmp_path / "dsm.tif", "correlation": tmp_path / "c.tif", "stats": tmp_path / "s.json"}
    with pytest.raises(InputError, match="the 1 dense tiles cover 1024 cells, the grid 8448"):
        merge_dense_tiles([tmp_path / "a.npz"], p, out)


def test_merge_applies_the_datum_check_as_the_untiled_stage(tiled, tmp_path):
    """The datum check reads the disk-backed mosaic at the targets and shifts every window alike."""
    import pandas as pd

    from kitegully.dense.datum import DatumParams, check_datum

    p0, untiled, parts = tiled
    dp = DatumParams.from_config({"enabled": True, "window_m": 0.3, "confidence": 0.95, "min_gcps": 4,
                                  "outlier_nmad": 3.0, "min_sd_m": 0.01})
    p = replace(p0, datum=dp)
    files = []
    for t, res in parts:
        save_dense_tile(tmp_path / f"{t.name}.npz", res, t, GRID, p)
        files.append(tmp_path / f"{t.name}.npz")
    whole = untiled.dsm
    # targets surveyed 0.2 m below the slope (a datum error the check must find), spread over all tiles
    xy = np.array([[-3.0, -3.0], [3.0, -3.0], [-3.0, 3.0], [3.0, 3.0], [0.0, 0.0], [1.5, -1.0]])
    surf = ds.slope()
    gcps = pd.DataFrame({"gcp_id": [f"g{i}" for i in range(len(xy))], "x": xy[:, 0], "y": xy[:, 1],
                         "z": surf(xy[:, 0], xy[:, 1]) - 0.2})
    ref = check_datum(whole, GRID, gcps, dp)
    assert ref.applied
    out = {"dsm": tmp_path / "dsm.tif", "correlation": tmp_path / "c.tif", "stats": tmp_path / "s.json",
           "datum": tmp_path / "datum_check.csv"}
    stats = merge_dense_tiles(files, p, out, gcps=gcps)
    assert stats["applied_offset_m"] == pytest.approx(ref.offset_m) and stats["datum"] == ref.summary()
    with rasterio.open(out["dsm"]) as src:
        np.testing.assert_array_equal(src.read(1), whole - np.float32(ref.offset_m))
    assert pd.read_csv(out["datum"])["dz_m"].to_numpy() == pytest.approx(ref.table["dz_m"].to_numpy())
