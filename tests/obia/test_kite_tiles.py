"""The kite-scale map as tile jobs (kitegully.obia.kite_tiles, issue 21): tiled equals untiled."""

from __future__ import annotations

import numpy as np
import pytest

from kitegully import InputError
from kitegully.io.raster import read_raster, write_raster
from kitegully.obia.kite import bare_soil_map
from kitegully.obia.kite_tiles import kite_histogram_tile, kite_map_tile, kite_tiles, merge_kite_tiles
from kitegully.terrain.tiling import TilingParams
from obia.test_kite import CELL, N, PARAMS, _site

TILE = 60  # cells: 4 x 4 blocks of the 240-cell site (>= 4 seed band widths of 15)


def _tiled(d, tiling, tile=TILE):
    names = tiling.names()
    hists = [d / f"h_{n}.npz" for n in names]
    for n, h in zip(names, hists):
        kite_histogram_tile(d / "orthophoto.tif", d / "dsm.tif", h, PARAMS, tile, tiling, n)
    maps = [d / f"m_{n}.npz" for n in names]
    for n, m in zip(names, maps):
        kite_map_tile(d / "orthophoto.tif", d / "dsm.tif", hists, m, PARAMS, tile, tiling, n)
    thr = merge_kite_tiles(maps[::-1], hists, d / "orthophoto.tif", d / "tiled.tif", PARAMS)  # any order
    return thr, read_raster(d / "tiled.tif")[0]


def test_tiled_map_equals_untiled(tmp_path):
    grid, rgb, dsm, truth = _site()
    write_raster(tmp_path / "orthophoto.tif", rgb, grid, nodata=None)
    write_raster(tmp_path / "dsm.tif", dsm, grid)
    ref_thr = bare_soil_map(tmp_path / "orthophoto.tif", tmp_path / "dsm.tif", tmp_path / "untiled.tif", PARAMS, TILE)
    ref = read_raster(tmp_path / "untiled.tif")[0]
    # 2 x 2 tile jobs of 2 x 2 blocks, and an uneven 3 x 2 split (2, 1, 1 block rows)
    for tiling in (TilingParams(N * CELL / 2, N * CELL, N * CELL), TilingParams(4.0, 8.0, 12.0)):
        thr, classes = _tiled(tmp_path, tiling)
        assert np.array_equal(classes, ref)  # every cell, the blocks' segments and classes unchanged
        assert thr.as_dict() == ref_thr.as_dict()  # the same global histogram and valley
    assert (ref == 0).any() and (ref == 1).any()  # a map with both classes, not a trivial one


def test_more_tiles_than_blocks_is_refused():
    with pytest.raises(InputError, match="obia.kite_scale.tile_cells 60"):
        kite_tiles((240, 240), 60, TilingParams(1.0, 12.0, 12.0))
    tiles = kite_tiles((250, 130), 60, TilingParams(6.0, 12.0, 12.0))
    assert [(t.r0, t.c0, t.h, t.w) for t in tiles] == [(0, 0, 120, 60), (0, 60, 120, 70), (120, 0, 130, 60), (120, 60, 130, 70)]


def test_histogram_tile_of_an_older_version_is_named(tmp_path):
    from kitegully.obia.kite_tiles import merged_threshold

    old = tmp_path / "h_r000_c000.npz"
    np.savez(old, counts=np.zeros(256 * 64, np.int64), r0=0, c0=0, h=60, w=60)  # counts only, as before session 42
    with pytest.raises(InputError, match=r"h_r000_c000.npz: histogram tile without local ranges .* rerun rule obia_kite_histogram"):
        merged_threshold([old], PARAMS)
