"""Tile grids of large sites (issue 21) and the tiled fill as the rules run it (files between jobs)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from kitegully import InputError
from kitegully.gully.params import GullyParams
from kitegully.gully.pipeline import map_gullies
from kitegully.gully.surface import tracing_surface
from kitegully.io.raster import GridSpec, read_raster, write_raster
from kitegully.seeds import rng_for
from kitegully.terrain.fill import priority_flood_fill
from kitegully.terrain.tiled_fill import SpillElevations, TileFill, TileSummary, fill_tile, finalise_tile, merge_tiles, read_tile_with_halo
from kitegully.terrain.tiling import TilingParams, split_grid, write_mosaic

CRS = "EPSG:32632"


def _dem(shape=(83, 121), seed_item="dem") -> np.ndarray:
    """Fractal-ish terrain with closed depressions, flats (ties) and nodata, float32 like a DSM."""
    rng = rng_for(0, "tiling", seed_item)
    h, w = shape
    yy, xx = np.mgrid[0:h, 0:w]
    z = 100.0 - 0.05 * xx + rng.normal(0.0, 0.3, shape)
    for _ in range(6):
        cy, cx, r = rng.uniform(0, h), rng.uniform(0, w), rng.uniform(4, 15)
        z -= 2.0 * np.exp(-((yy - cy) ** 2 + (xx - cx) ** 2) / r**2)
    z = np.round(z, 1)
    z[30:34, 50:57] = np.nan
    z[rng.random(shape) < 0.005] = np.nan
    return z.astype(np.float32)


def test_split_grid_partitions_exactly():
    tiles = split_grid((83, 121), 3, 5)
    cover = np.zeros((83, 121), int)
    for t in tiles:
        cover[t.r0 : t.r0 + t.h, t.c0 : t.c0 + t.w] += 1
    assert np.all(cover == 1)
    assert [t.tid for t in tiles] == list(range(15))
    assert max(t.h for t in tiles) - min(t.h for t in tiles) <= 1
    with pytest.raises(ValueError):
        split_grid((3, 3), 4, 1)


def test_tile_names_follow_from_the_config_alone():
    cfg = {"tiling": {"tile_m": 500.0, "extent": None}, "twin": {"extent": {"width_m": 2120.0, "height_m": 1500.0}}}
    p = TilingParams.from_config(cfg)
    assert p.counts == (3, 5)
    assert p.names()[0] == "r000_c000" and p.names()[-1] == "r002_c004" and len(p.names()) == 15
    # the same names on any raster shape: windows split whatever the rounding made of the grid
    assert [t.name for t in p.tiles((7501, 10600))] == p.names()
    with pytest.raises(InputError, match="tiling.extent"):
        TilingParams.from_config({"tiling": {"tile_m": 500.0, "extent": None}})
    with pytest.raises(InputError, match="tile r009_c000"):
        p.tile((7501, 10600), "r009_c000")


@pytest.mark.parametrize("counts", [(1, 1), (2, 3), (4, 7)])
def test_tiled_fill_through_files_equals_the_untiled_fill(tmp_path, counts):
    """The jobs' chain: window reads, per-tile .npz, merge of the summaries only, mosaic."""
    z = _dem()
    grid = GridSpec(500000.0, 4001000.0, 0.2, z.shape[1], z.shape[0], CRS)
    surface = tmp_path / "trace_surface.tif"
    write_raster(surface, z, grid)
    tiles = split_grid(z.shape, *counts)
    fills, sums = {}, []
    for t in tiles:  # gully_fill_tile
        tf = fill_tile(read_tile_with_halo(surface, t), t)
        fills[t.name] = tmp_path / f"{t.name}.fill.npz"
        tf.save(fills[t.name])
        tf.summary().save(tmp_path / f"{t.name}.summary.npz")
        sums.append(tmp_path / f"{t.name}.summary.npz")
    merge_tiles([TileSummary.load(p) for p in sums]).save(tmp_path / "spill.npz")  # gully_fill_merge
    spill = SpillElevations.load(tmp_path / "spill.npz")
    out = tmp_path / "filled.tif"  # gully_fill_mosaic
    write_mosaic(out, surface, tiles, lambda t: finalise_tile(TileFill.load(fills[t.name]), spill), dtype="float32")
    got, g2 = read_raster(out)
    ref, n_raised = priority_flood_fill(z, epsilon=0.0)
    assert n_raised > 0 and g2.transform == grid.transform
    # an ε = 0 fill only copies elevations: the float32 mosaic holds the float64 fill exactly
    assert np.array_equal(got.astype(np.float64), ref, equal_nan=True)


def test_map_gullies_with_the_tiled_fill_equals_the_untiled_chain(tmp_path):
    z = _dem((90, 140), "gully")
    grid = GridSpec(500000.0, 4001000.0, 0.2, z.shape[1], z.shape[0], CRS)
    params = GullyParams(sigma_m=2.0, depth_threshold_m=0.1, min_patch_volume_m3=0.01, water_min_area_m2=None,
                         trace_smoothing_m=0.4)
    hx, hy = np.array([500003.0, 500020.0]), np.array([4000990.0, 4000995.0])
    ref = map_gullies(z, grid, hx, hy, params)
    _, z_trace, _ = tracing_surface(z, grid, params)
    filled = np.empty(z.shape, dtype=z_trace.dtype)
    from kitegully.terrain.tiled_fill import tiled_priority_flood_fill

    filled[:] = tiled_priority_flood_fill(z_trace, 17)
    got = map_gullies(z, grid, hx, hy, params, filled=filled)
    assert got.n_raised == ref.n_raised > 0
    assert np.array_equal(got.network.cells, ref.network.cells)
    assert np.array_equal(got.gully, ref.gully)
    given = map_gullies(z, grid, hx, hy, params, filled=filled, trace_surface=z_trace)  # the tiled rules' path
    assert given.n_raised == ref.n_raised and np.array_equal(given.gully, ref.gully)
    # the gully_map rule passes the tracing surface as its GeoTIFF, read in the fill branch and dropped after it
    from kitegully.io.raster import write_raster

    write_raster(tmp_path / "trace_surface.tif", z_trace.astype(np.float32), grid)
    from_file = map_gullies(z, grid, hx, hy, params, filled=filled, trace_surface=tmp_path / "trace_surface.tif")
    assert from_file.n_raised == ref.n_raised and np.array_equal(from_file.network.cells, ref.network.cells)
    write_raster(tmp_path / "small.tif", z_trace[:-1].astype(np.float32), grid.window(0, 0, z.shape[0] - 1, z.shape[1]))
    with pytest.raises(ValueError, match="tracing surface has shape"):
        map_gullies(z, grid, hx, hy, params, filled=filled, trace_surface=str(tmp_path / "small.tif"))
    with pytest.raises(ValueError, match="only used with the filled DEM"):
        map_gullies(z, grid, hx, hy, params, trace_surface=z_trace)
    with pytest.raises(ValueError, match="flat_routing: resolve"):
        map_gullies(z, grid, hx, hy, GullyParams(flat_routing="epsilon"), filled=filled)


def test_least_cost_routing_with_the_tiled_rules_inputs_equals_the_untiled_call():
    z = _dem((90, 140), "gully")
    grid = GridSpec(500000.0, 4001000.0, 0.2, z.shape[1], z.shape[0], CRS)
    params = GullyParams(sigma_m=2.0, depth_threshold_m=0.1, min_patch_volume_m3=0.01, water_min_area_m2=None,
                         trace_smoothing_m=0.4, flat_routing="least_cost")
    hx, hy = np.array([500003.0, 500020.0]), np.array([4000990.0, 4000995.0])
    ref = map_gullies(z, grid, hx, hy, params)
    _, z_trace, _ = tracing_surface(z, grid, params)
    from kitegully.terrain.tiled_fill import tiled_priority_flood_fill

    filled = tiled_priority_flood_fill(z_trace, 17)
    got = map_gullies(z, grid, hx, hy, params, filled=filled, trace_surface=z_trace)
    assert got.n_flat_routed == ref.n_flat_routed > 0  # routes out of depressions found by the search
    assert np.array_equal(got.network.cells, ref.network.cells)
    assert np.array_equal(got.gully, ref.gully)


def test_the_default_sites_stay_untiled():
    from kitegully.config import load_yaml

    for site in ("kamech_twin", "tiny_twin"):
        assert "tiling" not in load_yaml(Path(__file__).resolve().parents[2] / "config" / "sites" / f"{site}.yaml")


def test_whole_block_tiles_partition_the_raster_into_whole_blocks():
    """Tiles hold whole blocks (the last cut by the edge), cover every cell once; too many tiles: one sentence."""
    from kitegully.terrain.tiling import TilingParams, whole_block_tiles

    tiles = whole_block_tiles((250, 130), 60, TilingParams(6.0, 12.0, 12.0), "kite-map", "the orthophoto",
                              "obia.kite_scale.tile_cells", "obia.kite_scale.tile_cells 60")
    cover = np.zeros((250, 130), int)
    for t in tiles:
        assert t.r0 % 60 == 0 and t.c0 % 60 == 0
        cover[t.r0:t.r0 + t.h, t.c0:t.c0 + t.w] += 1
    assert (cover == 1).all() and len(tiles) == 4
    with pytest.raises(InputError, match=r"gives 12 x 12 kite-map tiles but the orthophoto has only 5 x 3 blocks"):
        whole_block_tiles((250, 130), 60, TilingParams(1.0, 12.0, 12.0), "kite-map", "the orthophoto",
                          "obia.kite_scale.tile_cells", "obia.kite_scale.tile_cells 60")
