"""Tiled Priority-Flood (Barnes 2016) must equal the untiled ε = 0 fill bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from kitegully.seeds import rng_for
from kitegully.terrain.fill import priority_flood_fill
from kitegully.terrain.tiled_fill import (
    SpillElevations,
    TileFill,
    TileSummary,
    fill_tile,
    finalise_tile,
    merge_tiles,
    read_tile_with_halo,
    tile_grid,
    tile_with_halo,
    tiled_priority_flood_fill,
)


def _bits_equal(a: np.ndarray, b: np.ndarray) -> bool:
    """Same float64 bit patterns (NaN included), with -0.0 read as +0.0.

    The untiled kernel itself gives a zero elevation a sign that depends on the order
    cells were reached in (``-0.0 + ε`` with ε = 0 is ``+0.0``); the values are equal.
    """
    return a.shape == b.shape and np.array_equal((a + 0.0).view(np.int64), (b + 0.0).view(np.int64))


def _random_dem(item: str, shape=(61, 47), nodata=True) -> np.ndarray:
    """Noise + pits + plateaus (repeated values) + bowls + nodata holes."""
    rng = rng_for(0, "tiled_fill", item)
    h, w = shape
    yy, xx = np.mgrid[0:h, 0:w]
    z = rng.normal(0.0, 1.0, shape)
    # coarse plateaus: many exactly equal values
    z += np.round(rng.uniform(0, 3, (h // 6 + 1, w // 6 + 1))).repeat(6, 0).repeat(6, 1)[:h, :w]
    # big bowls (depressions that cross tile corners) and sharp pits
    for _ in range(4):
        cy, cx, r = rng.uniform(0, h), rng.uniform(0, w), rng.uniform(5, 20)
        z -= 6.0 * np.exp(-((yy - cy) ** 2 + (xx - cx) ** 2) / r**2)
    z[rng.random(shape) < 0.03] -= 5.0
    z = np.round(z, 1)  # ties everywhere
    if nodata:
        for _ in range(3):
            cy, cx = rng.integers(0, h), rng.integers(0, w)
            z[max(0, cy - 2) : cy + 3, max(0, cx - 3) : cx + 2] = np.nan
        z[rng.random(shape) < 0.01] = np.nan
    return z


@pytest.mark.parametrize("tile", [1, 2, 3, 7, 10, 16, 25, 47, 61, 100])
@pytest.mark.parametrize("item", ["a", "b", "c"])
def test_tiled_equals_untiled(tile, item):
    z = _random_dem(item)
    ref, _ = priority_flood_fill(z, epsilon=0.0)
    out = tiled_priority_flood_fill(z, tile)
    assert _bits_equal(out, ref)


@pytest.mark.parametrize("tile", [4, 9, 13])
def test_tiled_equals_untiled_without_nodata(tile):
    z = _random_dem("clean", shape=(40, 53), nodata=False)
    ref, n = priority_flood_fill(z, epsilon=0.0)
    assert n > 0
    assert _bits_equal(tiled_priority_flood_fill(z, tile), ref)


def test_depression_across_a_tile_corner():
    # a bowl centred exactly on the corner shared by four 10x10 tiles, its rim lowest far away
    yy, xx = np.mgrid[0:30, 0:30]
    z = 10.0 + 0.01 * ((yy - 10) ** 2 + (xx - 10) ** 2) ** 0.5
    z[8:13, 8:13] = 5.0
    z[0, 25] = 9.0
    ref, _ = priority_flood_fill(z, epsilon=0.0)
    out = tiled_priority_flood_fill(z, 10)
    assert _bits_equal(out, ref)
    # the pit rises to its spill level, which the per-tile fill alone cannot see
    tf = fill_tile(tile_with_halo(z, tile_grid(z.shape, 10)[0]), tile_grid(z.shape, 10)[0])
    assert tf.filled[9, 9] == 5.0
    assert out[9, 9] == ref[9, 9] > 10.0


def test_only_outlet_in_another_tile():
    # a closed rim everywhere except one notch on the DEM edge, in the far tile; the
    # depression covers tiles that see no outlet of their own
    z = np.full((30, 40), 20.0)
    z[1:-1, 1:-1] = 1.0
    z[5:25, 5:35] = np.linspace(0.0, 3.0, 30)[None, :]
    z[29, 37] = 7.5  # the only gap in the rim, in tile (2, 3) for tiles of 10
    ref, _ = priority_flood_fill(z, epsilon=0.0)
    assert ref[15, 15] == 7.5
    out = tiled_priority_flood_fill(z, 10)
    assert _bits_equal(out, ref)
    assert out[3, 3] == 7.5  # tile (0, 0) is raised to a spill found in tile (2, 3)


def test_outlet_is_nodata_across_the_tile_border():
    # the only outlet is a nodata cell in the neighbouring tile: the halo must see it
    z = np.full((20, 20), 10.0)
    z[1:-1, 1:-1] = 1.0
    z[10, 10] = np.nan  # first cell of tile (1, 1); its neighbours in tile (0, 0) drain to it
    ref, _ = priority_flood_fill(z, epsilon=0.0)
    out = tiled_priority_flood_fill(z, 10)
    assert _bits_equal(np.nan_to_num(out, nan=-1), np.nan_to_num(ref, nan=-1))
    assert out[9, 9] == 1.0


def test_passes_through_files(tmp_path):
    """The three passes as separate jobs exchanging files give the same fill."""
    z = _random_dem("files", shape=(35, 29))
    tiles = tile_grid(z.shape, 12)
    for t in tiles:
        tf = fill_tile(tile_with_halo(z, t), t)
        tf.save(tmp_path / f"{t.name}.npz")
        tf.summary().save(tmp_path / f"{t.name}.summary.npz")
    merge_tiles([TileSummary.load(tmp_path / f"{t.name}.summary.npz") for t in tiles]).save(tmp_path / "spill.npz")
    spill = SpillElevations.load(tmp_path / "spill.npz")
    out = np.empty(z.shape)
    for t in tiles:
        out[t.r0 : t.r0 + t.h, t.c0 : t.c0 + t.w] = finalise_tile(TileFill.load(tmp_path / f"{t.name}.npz"), spill)
    ref, _ = priority_flood_fill(z, epsilon=0.0)
    assert _bits_equal(out, ref)


def test_tile_grid_is_deterministic_and_covers_the_grid():
    tiles = tile_grid((25, 31), 10)
    assert [t.name for t in tiles][:4] == ["r000_c000", "r000_c001", "r000_c002", "r000_c003"]
    cover = np.zeros((25, 31), int)
    for t in tiles:
        cover[t.r0 : t.r0 + t.h, t.c0 : t.c0 + t.w] += 1
    assert (cover == 1).all()
    assert (tiles[-1].h, tiles[-1].w) == (5, 1)


def test_missing_tile_is_an_error():
    z = _random_dem("missing", shape=(20, 30), nodata=False)
    summaries = [fill_tile(tile_with_halo(z, t), t).summary() for t in tile_grid(z.shape, 10)]
    with pytest.raises(ValueError, match="missing r001_c001"):
        merge_tiles(summaries[:4] + summaries[5:])


def test_many_random_shapes_and_tiles():
    rng = rng_for(0, "tiled_fill", "shapes")
    for k in range(25):
        h, w = (int(v) for v in rng.integers(1, 40, 2))
        z = np.round(rng.normal(0, 1, (h, w)) + rng.uniform(-2, 2) * np.linspace(0, 1, w)[None, :], 1)
        z[rng.random((h, w)) < rng.uniform(0, 0.15)] = np.nan
        tile = int(rng.integers(1, 15))
        ref, _ = priority_flood_fill(z, epsilon=0.0)
        assert _bits_equal(tiled_priority_flood_fill(z, tile), ref), (k, h, w, tile)


def test_read_tile_with_halo_matches_array_halo(tmp_path):
    import rasterio
    from rasterio.transform import from_origin

    z = _random_dem("tif", shape=(23, 17)).astype(np.float32)
    path = tmp_path / "dem.tif"
    with rasterio.open(path, "w", driver="GTiff", width=17, height=23, count=1, dtype="float32", nodata=np.nan,
                       crs="EPSG:32632", transform=from_origin(0, 0, 0.2, 0.2)) as dst:
        dst.write(z, 1)
    for t in tile_grid(z.shape, 8):
        a = read_tile_with_halo(path, t)
        b = tile_with_halo(z.astype(np.float64), t)
        assert np.array_equal(a, b, equal_nan=True), t.name
