"""Orthophoto of a tiled site as tile jobs (issue 21): plan + 2 x 2 tiles + merge = untiled orthophoto."""

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
from kitegully.dense.ortho import orthophoto
from kitegully.dense.ortho_tiles import merge_ortho_tiles, ortho_tiles, plan_orthophoto, render_ortho_tile
from kitegully.io.raster import GridSpec, write_raster
from kitegully.seeds import rng_for
from kitegully.terrain.tiling import TilingParams

GRID = GridSpec(-4.8, 4.8, 0.1, 96, 88, "EPSG:32632")
TILING = TilingParams(tile_m=5.0, width_m=9.6, height_m=8.8)  # 2 x 2 tiles


def _params() -> DenseParams:
    base = DenseParams.from_config(load_yaml(REPO / "config/sites/tiny_twin.yaml")["dense"])
    # blocks of 64 / 2 = 32 DSM cells: 3 x 3 blocks, tiles of 1-2 blocks; 1 m occlusion margin (10 cells)
    return replace(base, cell_m=0.1, orthophoto=replace(base.orthophoto, upsample=2, tile_cells=64, overlap_m=1.0))


def test_windows_are_whole_blocks_and_too_many_tiles_named():
    tiles = ortho_tiles(GRID.shape, _params(), TILING)
    assert [(t.r0, t.c0, t.h, t.w) for t in tiles] == [(0, 0, 32, 32), (0, 32, 32, 64), (32, 0, 56, 32), (32, 32, 56, 64)]
    with pytest.raises(InputError, match=r"tiling.tile_m: 2 m gives 5 x 5 orthophoto tiles but the DSM has only 3 x 3 blocks"):
        ortho_tiles(GRID.shape, _params(), TilingParams(tile_m=2.0, width_m=9.6, height_m=8.8))


def test_tiled_orthophoto_equals_untiled(tmp_path):
    views, imgs, _ = ds.block(ds.pillars(), rng_for(12, "test_ortho_tiles", "pillars"))
    xs, ys = GRID.cell_centres()
    dsm = ds.pillars()(*np.meshgrid(xs, ys)).astype(np.float32)
    yy, xx = np.mgrid[0:GRID.height, 0:GRID.width]
    dsm[np.hypot(yy - 30, xx - 33) < 9] = np.nan  # a hole across the tile seams: filled from beyond the tile
    dsm[rng_for(12, "test_ortho_tiles", "holes").random(dsm.shape) < 0.05] = np.nan
    p = _params()
    oc = p.orthophoto
    ref, og, src = orthophoto(views, dsm, GRID, oc.upsample, oc.tile_cells, oc.overlap_m, oc.occlusion_tolerance_m,
                              p.max_cached_images, imgs)
    assert (src >= 0).mean() > 0.5
    write_raster(tmp_path / "dsm.tif", dsm, GRID)
    plan = plan_orthophoto(views, tmp_path / "dsm.tif", p, tmp_path / "filled.tif", tmp_path / "plan.json")
    assert plan["block_cells"] == 32 and json.loads((tmp_path / "plan.json").read_text())["finest_level"] == plan["finest_level"]
    files = []
    for t in ortho_tiles(GRID.shape, p, TILING):
        f = tmp_path / f"{t.name}.npz"
        render_ortho_tile(views, tmp_path / "filled.tif", tmp_path / "plan.json", p, TILING, t.name, f, arrays=imgs)
        files.append(f)
    stats = merge_ortho_tiles(files[::-1], tmp_path / "dsm.tif", tmp_path / "ortho.tif", tmp_path / "stats.json")
    assert stats["tile_jobs"] == 4
    with rasterio.open(tmp_path / "ortho.tif") as o:
        assert o.transform == og.transform and o.count == ref.shape[0]
        assert np.array_equal(o.read(), ref)  # bit for bit
        assert np.array_equal(o.dataset_mask() > 0, src >= 0)
        ov, blocks = o.overviews(1), o.block_shapes
    write_raster(tmp_path / "ref.tif", ref, og, mask=src >= 0, overview_resampling="average")
    with rasterio.open(tmp_path / "ref.tif") as r:
        assert r.overviews(1) == ov and r.block_shapes == blocks  # the untiled stage's COG layout
    from rio_cogeo.cogeo import cog_validate
    assert cog_validate(tmp_path / "ortho.tif", quiet=True)[0]
    with pytest.raises(InputError, match="orthophoto tiles cover"):
        merge_ortho_tiles(files[:3], tmp_path / "dsm.tif", tmp_path / "o2.tif", tmp_path / "s2.json")
