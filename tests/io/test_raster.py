"""Raster (array + grid + nodata) and the GridSpec helpers that replace hand-written
geotransform arithmetic. The helpers must give the same bits as the expressions they
replaced (the ``old_*`` formulas below are copied from the code before issue 13)."""

from __future__ import annotations

import numpy as np
import pytest
import rasterio
from affine import Affine

from kitegully import InputError
from kitegully.io.raster import GridSpec, Raster, read_raster, write_raster

CRS = "EPSG:32632"
# awkward origin and cell so rounding differences would show
GRID = GridSpec(500123.37, 4100987.11, 0.137, 37, 29, CRS)


# ------------------------------------------------------------------ GridSpec helpers
def test_xy_inverts_rowcol_and_matches_the_hand_formula():
    rng = np.random.default_rng(1)
    r = rng.integers(-5, 40, 500)
    c = rng.integers(-5, 40, 500)
    x, y = GRID.xy(r, c)
    assert np.array_equal(x, GRID.x0 + (c + 0.5) * GRID.cell)
    assert np.array_equal(y, GRID.y0 - (r + 0.5) * GRID.cell)
    rr, cc = GRID.rowcol(x, y)
    np.testing.assert_allclose(rr, r, atol=1e-6)
    np.testing.assert_allclose(cc, c, atol=1e-6)


def test_flat_xy_and_unravel():
    flat = np.array([0, 1, GRID.width, GRID.width * GRID.height - 1], np.int64)
    r, c = GRID.unravel(flat)
    assert r.tolist() == [0, 0, 1, GRID.height - 1]
    assert c.tolist() == [0, 1, 0, GRID.width - 1]
    xy = GRID.flat_xy(flat)
    # old gully/network.py _coords
    rr = flat // GRID.width
    cc = flat - rr * GRID.width
    old = np.column_stack([GRID.x0 + (cc + 0.5) * GRID.cell, GRID.y0 - (rr + 0.5) * GRID.cell])
    assert xy.shape == (4, 2) and np.array_equal(xy, old)


@pytest.mark.parametrize("r0, c0, nr, nc", [(0, 0, 29, 37), (3, 5, 7, 11), (-4, -6, 40, 50), (20, 30, 15, 15)])
def test_cell_centres_of_a_block_match_the_old_tile_formula(r0, c0, nr, nc):
    xs, ys = GRID.cell_centres(r0, c0, nr, nc)
    # old twin/site.py compute_tile / compute_phase
    assert np.array_equal(xs, GRID.x0 + (c0 + np.arange(nc) + 0.5) * GRID.cell)
    assert np.array_equal(ys, GRID.y0 - (r0 + np.arange(nr) + 0.5) * GRID.cell)


def test_cell_centres_default_is_the_whole_grid():
    xs, ys = GRID.cell_centres()
    assert xs.shape == (GRID.width,) and ys.shape == (GRID.height,)
    assert np.array_equal(xs, GRID.x0 + (np.arange(GRID.width) + 0.5) * GRID.cell)
    assert np.array_equal(ys, GRID.y0 - (np.arange(GRID.height) + 0.5) * GRID.cell)


def test_cell_centres_with_margin_match_old_dense_surface_formula():
    off = np.array([500000.25, 4100000.75])
    O, T = 16, 64
    local = GRID.shifted(-off[0], -off[1])
    xs, ys = local.cell_centres(-O, -O, GRID.height + T + 2 * O, GRID.width + T + 2 * O)
    old_x = GRID.x0 - off[0] + (np.arange(-O, GRID.width + T + O) + 0.5) * GRID.cell
    old_y = GRID.y0 - off[1] - (np.arange(-O, GRID.height + T + O) + 0.5) * GRID.cell
    assert np.array_equal(xs, old_x) and np.array_equal(ys, old_y)


def test_index_and_contains_on_edges():
    g = GridSpec(10.0, 20.0, 2.0, 3, 2, CRS)  # x 10..16, y 16..20
    r, c = g.index(np.array([10.0, 11.9, 12.0, 15.999, 16.0, 9.99]), np.array([20.0, 19.0, 18.0, 16.001, 17.0, 19.0]))
    assert c.tolist() == [0, 0, 1, 2, 3, -1]
    assert r.tolist() == [0, 0, 1, 1, 1, 0]
    assert g.contains(np.array([10.0, 16.0, 13.0, 13.0]), np.array([20.0, 17.0, 16.0, 20.01])).tolist() == [True, False, False, False]
    assert r.dtype == np.int64 and c.dtype == np.int64


def test_window_refined_coarsened_shifted_resampled():
    w = GRID.window(3, 5, 4, 6)
    assert (w.x0, w.y0, w.cell, w.width, w.height, w.crs) == (GRID.x0 + 5 * GRID.cell, GRID.y0 - 3 * GRID.cell, GRID.cell, 6, 4, CRS)
    # a window's bounds are the old hand-written ``carve`` box
    x0, y0 = GRID.x0 + 5 * GRID.cell, GRID.y0 - 3 * GRID.cell
    assert w.bounds == (x0, y0 - 4 * GRID.cell, x0 + 6 * GRID.cell, y0)
    f = GRID.refined(4)
    assert (f.x0, f.y0, f.cell, f.width, f.height) == (GRID.x0, GRID.y0, GRID.cell / 4, 4 * GRID.width, 4 * GRID.height)
    assert f.bounds[0] == GRID.bounds[0] and f.bounds[3] == GRID.bounds[3]
    k = GRID.coarsened(4)
    assert (k.cell, k.width, k.height) == (GRID.cell * 4, GRID.width // 4, GRID.height // 4)
    s = GRID.shifted(-500000.0, -4100000.0)
    assert s.x0 == GRID.x0 - 500000.0 and s.y0 == GRID.y0 - 4100000.0 and s.shape == GRID.shape
    down = GRID.resampled(0.5)
    up = GRID.resampled(0.5, cover=True)
    assert down.width == int(np.floor(37 * 0.137 / 0.5)) == 10 and up.width == 11
    assert up.bounds[2] >= GRID.bounds[2] and down.bounds[2] <= GRID.bounds[2]


def test_centre_and_from_transform():
    assert GRID.centre == (GRID.x0 + GRID.width * GRID.cell / 2, GRID.y0 - GRID.height * GRID.cell / 2)
    g = GridSpec.from_transform(GRID.transform, GRID.width, GRID.height, CRS)
    assert g == GRID
    assert GRID.transform == Affine(GRID.cell, 0, GRID.x0, 0, -GRID.cell, GRID.y0)


# ------------------------------------------------------------------ Raster
def test_raster_round_trip_float_nan_nodata(tmp_path):
    z = np.arange(GRID.height * GRID.width, dtype=np.float32).reshape(GRID.shape)
    z[2, 3] = np.nan
    r = Raster(z, GRID)
    assert np.isnan(r.nodata)
    r.write(tmp_path / "z.tif", tags={"units": "m"})
    back = Raster.read(tmp_path / "z.tif")
    assert back.grid == GRID and back.data.dtype == np.float32
    assert np.array_equal(back.data, z, equal_nan=True)
    assert back.valid.sum() == z.size - 1 and not back.valid[2, 3]
    assert back.transform == GRID.transform and back.crs == CRS and back.bounds == GRID.bounds


def test_float_sentinel_nodata_becomes_nan_on_read(tmp_path):
    z = np.ones(GRID.shape, np.float32)
    z[0, 0] = -9999.0
    write_raster(tmp_path / "s.tif", z, GRID, nodata=-9999.0)
    r = Raster.read(tmp_path / "s.tif")
    assert np.isnan(r.data[0, 0]) and np.isnan(r.nodata) and r.valid.sum() == z.size - 1
    data, grid = read_raster(tmp_path / "s.tif")
    assert grid == GRID and np.array_equal(data, r.data, equal_nan=True)


def test_integer_raster_keeps_its_sentinel(tmp_path):
    a = np.zeros((2,) + GRID.shape, np.uint8)
    a[:, 1, 1] = 255
    a[0, 2, 2] = 255
    Raster(a, GRID, 255).write(tmp_path / "i.tif", band_names=["a", "b"])
    r = Raster.read(tmp_path / "i.tif", band=None)
    assert r.nodata == 255 and r.data.shape == (2,) + GRID.shape
    # all bands must be valid
    assert not r.valid[1, 1] and not r.valid[2, 2] and r.valid[3, 3] and r.valid.sum() == GRID.width * GRID.height - 2
    with rasterio.open(tmp_path / "i.tif") as src:
        assert src.descriptions == ("a", "b")


def test_with_data_keeps_grid_and_shape_is_checked():
    r = Raster(np.zeros(GRID.shape, np.float32), GRID)
    m = r.with_data(np.ones(GRID.shape, np.uint8), nodata=0)
    assert m.grid is GRID and m.nodata == 0 and m.valid.all()
    with pytest.raises(ValueError, match="does not match grid"):
        Raster(np.zeros((3, 3), np.float32), GRID)


def test_missing_file_is_an_input_error(tmp_path):
    with pytest.raises(InputError, match="cannot open raster"):
        Raster.read(tmp_path / "nope.tif")


def test_covering_grid_snaps_outward_like_the_old_dense_site_grid():
    rng = np.random.default_rng(3)
    for _ in range(200):
        xmin, ymin = rng.uniform(-1e6, 1e6, 2)
        xmax, ymax = xmin + rng.uniform(0.01, 500), ymin + rng.uniform(0.01, 500)
        cell = float(rng.choice([0.05, 0.1, 0.2, 0.25, 0.5, 1.0]))
        g = GridSpec.covering((xmin, ymin, xmax, ymax), cell, CRS)
        # old dense/stage.py site_grid
        x0 = np.floor(xmin / cell) * cell
        y0 = np.ceil(ymax / cell) * cell
        old = GridSpec(float(x0), float(y0), cell, int(np.ceil((xmax - x0) / cell)), int(np.ceil((y0 - ymin) / cell)), CRS)
        assert g == old
        bx0, by0, bx1, by1 = g.bounds
        assert bx0 <= xmin and by1 >= ymax and bx1 >= xmax - 1e-6 and by0 <= ymin + 1e-6


@pytest.mark.parametrize("problem, match", [("rotated", "rotated or not north-up"), ("south-up", "rotated or not north-up"),
                                            ("no_crs", "has no CRS"), ("non_square", "cells are not square")])
def test_readers_check_the_grid_once(tmp_path, problem, match):
    """grid_of: the checks that Raster.read, read_raster and the tiled OBIA reader share."""
    from kitegully.io.raster import grid_of

    path = tmp_path / f"{problem}.tif"
    t = {"rotated": Affine(GRID.cell, 0.01, GRID.x0, 0.01, -GRID.cell, GRID.y0),
         "south-up": Affine(GRID.cell, 0, GRID.x0, 0, GRID.cell, GRID.y0),
         "no_crs": GRID.transform,
         "non_square": Affine(GRID.cell, 0, GRID.x0, 0, -1.5 * GRID.cell, GRID.y0)}[problem]
    with rasterio.open(path, "w", driver="GTiff", width=GRID.width, height=GRID.height, count=1, dtype="float32",
                       crs=None if problem == "no_crs" else CRS, transform=t) as dst:
        dst.write(np.zeros((1,) + GRID.shape, np.float32))
    with pytest.raises(InputError, match=match) as err:
        Raster.read(path)
    assert str(path) in str(err.value)
    with rasterio.open(path) as src, pytest.raises(InputError, match=match):
        grid_of(src, path)
