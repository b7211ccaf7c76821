"""Tiled morphometry (issue 21): tile jobs that own polygons by centroid give the whole-grid products."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
import shapely

from kitegully.config import load_yaml
from kitegully.io.raster import GridSpec
from kitegully.polygons.stage import PolygonParams, measure_polygons
from kitegully.polygons.tiles import WindowGrid, margin_cells, measure_tile, merge_morphometry, merged_summary, owners, polygons_window
from kitegully.terrain.tiling import split_grid

from .polygon_synthetic import CRS


def two_gullies() -> tuple[np.ndarray, GridSpec]:
    """A plane falling south with a straight U gully and a slanting V gully, 120 x 100 m at 0.5 m."""
    grid = GridSpec(578600.0, 4081600.0, 0.5, 200, 240, CRS)  # the default site's origin
    xs, ys = grid.cell_centres()
    x, y = np.meshgrid(xs - xs[0], ys - ys[-1])
    z = 100.0 + 0.03 * y
    d1 = np.abs(x - 30.0)  # along y: crosses the tile row border
    z -= np.where((d1 < 4.0) & (y < 110.0), 2.0 * (1.0 - (d1 / 4.0) ** 4), 0.0)
    d2 = np.abs(x - (45.0 + 0.35 * (110.0 - y)))  # slanting east: crosses the tile column border (x = 50 m)
    z -= np.where((d2 < 3.0) & (y < 112.0) & (y > 5.0), 1.5 * (1.0 - d2 / 3.0), 0.0)
    return z.astype(np.float32), grid


@pytest.fixture(scope="module")
def site_run(repo_root):
    p = PolygonParams.from_config(load_yaml(repo_root / "config" / "sites" / "kamech_twin.yaml")["polygons"])
    z, grid = two_gullies()
    return p, measure_polygons(z, grid, p), measure_polygons(z, grid, p, morphometry=False)


def test_every_polygon_has_one_owner_and_polygons_cross_the_borders(site_run):
    p, res, _ = site_run
    tiles = split_grid(res.dem.shape, 2, 2)
    polys = res.polygons[p.morph_threshold_m]
    own = owners(polys, res.grid, tiles)
    assert len(polys) >= 2 and set(own) <= {t.name for t in tiles} and len(set(own)) >= 2
    # the border row and column of the 2 x 2 tiles cut through polygons
    row_b, col_b = tiles[3].r0, tiles[3].c0
    xb, yb = res.grid.x0 + col_b * res.grid.cell, res.grid.y0 - row_b * res.grid.cell
    assert any(g.intersects(shapely.LineString([(xb, yb - 500), (xb, yb + 500)])) for g in polys.geometry)
    assert any(g.intersects(shapely.LineString([(xb - 500, yb), (xb + 500, yb)])) for g in polys.geometry)
    win = polygons_window(polys.iloc[:1], res.grid, margin_cells(p, res.grid.cell))
    assert win[0] % 2 == 0 and win[1] % 2 == 0  # numpy rounds halves to even: odd offsets would move rim samples
    assert win[0] >= 0 and win[0] + win[2] <= res.grid.height and margin_cells(p, 0.5) == 37  # (4.5 rim + 4.5 banks + 2 x 4.0 ground, across and along + 0.5) / 0.5 + 2


def test_tile_jobs_merge_to_the_whole_grid_morphometry(site_run):
    p, res, part = site_run
    arrays = {"labels": res.labels[p.morph_threshold_m], "dem": res.dem, "level": res.level, "rims": res.rims}

    def read(name, r0, c0, h, w):
        return arrays[name][r0:r0 + h, c0:c0 + w]

    tiles = split_grid(res.dem.shape, 2, 2)
    parts = [measure_tile(res.polygons[p.morph_threshold_m], res.grid, t, read, p, tiles) for t in tiles]
    axes, sections, morph = merge_morphometry(parts, res.grid.crs)
    assert len(sections) >= 10
    pd.testing.assert_frame_equal(morph, res.morphometry, check_exact=False, rtol=1e-9, atol=1e-9)
    for got, want in ((axes, res.axes), (sections, res.sections)):
        pd.testing.assert_frame_equal(pd.DataFrame(got.drop(columns="geometry")), pd.DataFrame(want.drop(columns="geometry")),
                                      check_exact=False, rtol=1e-9, atol=1e-9)
        assert all(a.equals_exact(b, 1e-9) for a, b in zip(got.geometry, want.geometry))
    # without step 6 the map job's products are the same; the summary rebuilt from the tiles has the same rows
    assert all(np.array_equal(part.labels[t], res.labels[t]) for t in p.thresholds_m)
    assert np.array_equal(part.level, res.level) and np.array_equal(part.rims, res.rims) and len(part.sections) == 0
    summary = merged_summary(part.summary, axes, sections, morph, p, 1.0, len(tiles))
    untimed = lambda s: s[~s["quantity"].str.startswith("time ")].reset_index(drop=True)  # noqa: E731
    pd.testing.assert_frame_equal(untimed(summary), untimed(res.summary))


def test_window_grid_maps_points_to_cells_exactly_as_the_whole_grid():
    grid = GridSpec(578600.0, 4081600.0, 0.5, 1200, 800, CRS)
    rng = np.random.default_rng(0)
    x = 578600.0 + np.round(rng.uniform(0, 600, 10000) * 8) / 8  # on the rim search's quarter-cell lattice too
    y = 4081600.0 - np.round(rng.uniform(0, 400, 10000) * 8) / 8
    r, c = grid.rowcol(x, y)
    for r0, c0 in ((204, 70), (339, 317)):
        wr, wc = WindowGrid.of(grid, r0, c0, 100, 100).rowcol(x, y)
        assert np.array_equal(wr + r0, r) and np.array_equal(wc + c0, c)
        assert np.array_equal(np.round(wr) + r0, np.round(r)) == (r0 % 2 == 0 and c0 % 2 == 0)
        xs, ys = WindowGrid.of(grid, r0, c0, 100, 100).xy(np.arange(5), np.arange(5))
        assert np.array_equal(xs, grid.xy(np.arange(5) + r0, np.arange(5) + c0)[0])
