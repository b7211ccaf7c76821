"""Volumes of a known pit and mound lie within their stated uncertainty; variogram and masks."""

import geopandas as gpd
import numpy as np
from affine import Affine
import pytest
from change.change_synth import CRS, grid, pair
from scipy import ndimage
from shapely.geometry import box

from kitegully.change import budget as bg
from kitegully.change.params import ChangeParams
from kitegully.change.uncertainty import detect, propagate
from kitegully.seeds import rng_for

SD = 0.05


def test_pit_and_mound_volumes_within_uncertainty():
    g, z1, z2, change = pair(SD)
    dod = z2 - z1
    sigma = propagate(SD, SD, dod.shape)
    det = detect(dod, sigma, ChangeParams())
    groups = [bg.MaskGroup("site", np.ones(dod.shape, bool), "test"), bg.MaskGroup("pit", change < 0, "test"),
              bg.MaskGroup("mound", change > 0, "test")]
    b = bg.compute_budgets(dod, sigma, det, groups, g.cell, None).set_index(["mask", "method"])
    a = g.cell**2
    for mask, true_net in (("site", change.sum() * a), ("pit", change[change < 0].sum() * a), ("mound", change[change > 0].sum() * a)):
        raw = b.loc[(mask, "raw")]
        assert abs(raw["net_m3"] - true_net) <= 2 * raw["net_sd_independent_m3"], mask
    assert b.loc[("site", "raw"), "net_sd_independent_m3"] == pytest.approx(a * SD * np.sqrt(2) * np.sqrt(dod.size), rel=1e-3)
    # thresholded at 95 %: the pit's erosion and the mound's deposition, less the thin rims below the LoD
    assert b.loc[("pit", "probabilistic"), "erosion_m3"] == pytest.approx(-change[change < 0].sum() * a, rel=0.1)
    assert b.loc[("mound", "probabilistic"), "deposition_m3"] == pytest.approx(change[change > 0].sum() * a, rel=0.1)


def test_correlated_noise_needs_the_correlated_estimate():
    """With spatially correlated errors the independent-cell SD is far too small; the variogram one covers the error."""
    g = grid(300, cell=1.0)
    rng = rng_for(7, "test", "corr")
    f = ndimage.gaussian_filter(rng.standard_normal((g.height, g.width)), 10.0, mode="wrap")
    err = (0.05 * f / f.std() + 0.03 * rng.standard_normal(f.shape)).astype(np.float32)
    sigma = np.full(err.shape, np.sqrt(0.05**2 + 0.03**2), np.float32)
    ok = np.ones(err.shape, bool)
    emp = bg.empirical_variogram(err / sigma, g, ok, 120.0, 25, 3000, 1)
    vg = bg.fit_variogram(emp, g.cell, 120.0)
    assert vg.f_nugget == pytest.approx(0.03**2 / 0.0034, abs=0.1)
    assert 10.0 < max(vg.ranges_m) < 80.0
    # volume of pure error over a 60 x 60 m square, SDs from both estimates
    sub = (slice(100, 160), slice(100, 160))
    row = bg.budget_row(err[sub], sigma[sub], np.ones((60, 60), bool), g.cell, vg)
    assert row["net_sd_correlated_m3"] > 10 * row["net_sd_independent_m3"]
    # across many 60 x 60 squares the correlated SD matches the spread of the error volumes
    vols = [err[i:i + 60, j:j + 60].sum() for i in range(0, 240, 60) for j in range(0, 240, 60)]
    assert np.std(vols) == pytest.approx(row["net_sd_correlated_m3"], rel=0.6)


def test_correlation_factor_limits():
    emp = None
    vg = bg.Variogram(0.5, (0.5,), (10.0,), emp)
    assert bg.correlation_factor(1.0, 1.0, vg) == pytest.approx(1.0, abs=0.06)   # one cell: its own variance
    big = bg.correlation_factor(1e6, 1.0, vg)
    assert big == pytest.approx(0.5 * 1e-6 + 0.5 * 100 / (5 * 1e6 / np.pi), rel=1e-6)


def test_vector_masks_by_column(tmp_path):
    g, z1, z2, change = pair(SD)
    x0, y0 = g.x0, g.y0
    polys = gpd.GeoDataFrame({"gully_id": [1, 2]}, geometry=[box(x0 + 20, y0 - 40, x0 + 40, y0 - 20),
                                                          box(x0 + 60, y0 - 75, x0 + 80, y0 - 55)], crs=CRS)
    polys.to_file(tmp_path / "m.gpkg")
    groups = bg.mask_groups([{"name": "gully", "file": str(tmp_path / "m.gpkg"), "by": "gully_id"}], g)
    assert [x.name for x in groups] == ["site", "gully", "gully:1", "gully:2"]
    assert groups[2].mask.sum() * g.cell**2 == pytest.approx(400.0)
    dod = change.astype(np.float32)
    sigma = propagate(SD, SD, dod.shape)
    b = bg.compute_budgets(dod, sigma, {}, groups, g.cell, None).set_index("mask")
    assert b.loc["gully:1", "net_m3"] == pytest.approx(change.sum() * g.cell**2 * 0 + (change[groups[2].mask].sum() * g.cell**2))
    assert b.loc["gully:1", "net_m3"] < 0 < b.loc["gully:2", "net_m3"]


def test_offset_uncertainty_from_stable_cells():
    """Offset SD of a fit on n scattered cells: ~1/√n for white errors, ~the sill share for long-range ones."""
    rng = np.random.default_rng(0)
    rows, cols = rng.integers(0, 1000, 2000), rng.integers(0, 1000, 2000)
    white = bg.Variogram(1.0, (), (), None)
    assert bg.mean_correlation(rows, cols, 1.0, white, 2000, 1) == pytest.approx(1 / 2000, rel=0.01)
    long = bg.Variogram(0.5, (0.5,), (1e6,), None)  # half the variance shared by all cells
    assert bg.mean_correlation(rows, cols, 1.0, long, 2000, 1) == pytest.approx(0.5, abs=0.01)
    row = bg.budget_row(np.zeros((10, 10)), np.full((10, 10), 0.1), np.ones((10, 10), bool), 1.0, white, coreg_sd_m=0.01)
    assert row["net_sd_coregistration_m3"] == pytest.approx(1.0)
    assert row["net_sd_m3"] == pytest.approx(np.hypot(row["net_sd_correlated_m3"], 1.0))


def test_polygon_groups_are_blocks_equal_to_full_rasterisation(tmp_path):
    """Each ``by`` polygon is rasterised on its own block: the same cells and the same budgets as a full map, a fraction of the memory."""
    from rasterio import features
    g, z1, z2, change = pair(SD)
    x0, y0 = g.x0, g.y0
    rng = rng_for(3, "test", "blocks")
    geoms = []
    for _ in range(40):
        cx, cy = x0 + rng.uniform(2, g.width * g.cell - 2), y0 - rng.uniform(2, g.height * g.cell - 2)
        geoms.append(box(cx - rng.uniform(0.3, 6), cy - rng.uniform(0.3, 6), cx + rng.uniform(0.3, 6), cy + rng.uniform(0.3, 6)))
    geoms.append(box(x0 - 5, y0 - 10, x0 + 3.3, y0 + 5))        # overlaps the grid's corner
    geoms.append(box(x0 - 50, y0 + 10, x0 - 40, y0 + 20))       # off the grid: an empty block, the row is kept
    polys = gpd.GeoDataFrame({"gid": range(len(geoms))}, geometry=geoms, crs=CRS)
    polys.to_file(tmp_path / "m.gpkg")
    groups = bg.mask_groups([{"name": "g", "file": str(tmp_path / "m.gpkg"), "by": "gid", "unstable": True}], g)
    per = groups[2:]
    assert len(per) == len(geoms)
    for grp, geom in zip(per, geoms):
        full = features.rasterize([(geom, 1)], out_shape=(g.height, g.width), transform=g.transform, fill=0, dtype="uint8").astype(bool)
        np.testing.assert_array_equal(grp.mask, full)
        assert grp.local.size < 0.05 * full.size
    assert per[-1].local.size == 0 and not per[-1].mask.any()
    np.testing.assert_array_equal(bg.unstable_union([{"name": "g", "unstable": True}], groups, change.shape), groups[1].mask)
    dod = change.astype(np.float32)
    sigma = propagate(SD, SD, dod.shape)
    det = detect(dod, sigma, ChangeParams())
    blocks = bg.compute_budgets(dod, sigma, det, groups, g.cell, None)
    full = bg.compute_budgets(dod, sigma, det, [bg.MaskGroup(x.name, x.mask, x.source, x.order) for x in groups], g.cell, None)
    pd_testing = pytest.importorskip("pandas.testing")
    pd_testing.assert_frame_equal(blocks, full)                   # same cells in the same order: equal sums, not just close


@pytest.mark.parametrize("split_vertices", [50_000, 20])
def test_masks_on_a_window_equal_the_whole_grid_cropped(tmp_path, monkeypatch, split_vertices):
    """A polygon much larger than a tile, with many holes, clipped to the tile: the same cells as rasterised on the whole grid."""
    from rasterio import features
    from shapely.geometry import Polygon
    g, *_ = pair(SD)
    x0, y0, c = g.x0, g.y0, g.cell
    rng = rng_for(5, "test", "holes")
    holes = []
    for _ in range(60):
        hx, hy = x0 + rng.uniform(5, g.width * c - 5), y0 - rng.uniform(5, g.height * c - 5)
        r = rng.uniform(0.2, 2.0)
        holes.append([(hx - r, hy - r), (hx + r, hy - r * 0.7), (hx + r * 0.6, hy + r), (hx - r, hy + r * 0.9)])
    holes = [h for k, h in enumerate(holes) if all(Polygon(h).disjoint(Polygon(o)) for o in holes[:k])]
    outer = [(x0 - 30, y0 + 30), (x0 + g.width * c + 30, y0 + 25), (x0 + g.width * c + 20, y0 - g.height * c - 30), (x0 - 25, y0 - g.height * c - 20)]
    gpd.GeoDataFrame({"k": [1]}, geometry=[Polygon(outer, holes)], crs=CRS).to_file(tmp_path / "big.gpkg")
    shifted = Affine.translation(bg.TIE_SHIFT_M, -bg.TIE_SHIFT_M) * g.transform  # each centre tested 0.1 mm east, south
    whole = features.rasterize([(Polygon(outer, holes), 1)], out_shape=(g.height, g.width), transform=shifted, fill=0, dtype="uint8").astype(bool)
    spec = [{"name": "bare", "file": str(tmp_path / "big.gpkg"), "by": "k"}]
    monkeypatch.setattr(bg, "SPLIT_VERTICES", split_vertices)    # 20: the grid is halved down to 64 cells
    for r0, c0, h, w in ((0, 0, g.height, g.width), (7, 11, 33, 41), (g.height - 20, g.width - 25, 20, 25)):
        groups = bg.mask_groups(spec, g.window(r0, c0, h, w))
        np.testing.assert_array_equal(groups[1].mask, whole[r0:r0 + h, c0:c0 + w])
        np.testing.assert_array_equal(groups[2].mask, whole[r0:r0 + h, c0:c0 + w])


@pytest.mark.parametrize("split_vertices", [50_000, 20])
def test_polygon_edges_through_cell_centres_are_decided_alike_in_every_window(tmp_path, monkeypatch, split_vertices):
    """A mask polygonised from a raster of half the cell (the kite bare-soil map on the DoD grid) has edges through
    cell centres; every window, split or not, decides those centres as the whole grid does."""
    from shapely.geometry import box
    from shapely.ops import unary_union
    g, *_ = pair(SD)
    x0, y0, half = g.x0, g.y0, g.cell / 2
    rng = rng_for(7, "test", "ties")
    fine = rng.random((2 * g.height, 2 * g.width)) < 0.5  # a half-cell raster: its edges run through the centres
    fine = np.kron(rng.random((g.height // 5, g.width // 5)) < 0.5, np.ones((10, 10), bool)) ^ (fine & (rng.random(fine.shape) < 0.05))
    r, c = np.nonzero(fine)
    poly = unary_union([box(x0 + cc * half, y0 - (rr + 1) * half, x0 + (cc + 1) * half, y0 - rr * half) for rr, cc in zip(r, c)])
    gpd.GeoDataFrame({"k": [1]}, geometry=[poly], crs=CRS).to_file(tmp_path / "fine.gpkg")
    spec = [{"name": "bare", "file": str(tmp_path / "fine.gpkg"), "by": None}]
    monkeypatch.setattr(bg, "SPLIT_VERTICES", split_vertices)
    whole = bg.mask_groups(spec, g)[1].mask
    assert 0.2 < whole.mean() < 0.8
    for r0, c0, h, w in ((7, 11, 33, 41), (0, 100, 200, 100), (123, 0, 77, 200), (50, 50, 101, 99)):
        np.testing.assert_array_equal(bg.mask_groups(spec, g.window(r0, c0, h, w))[1].mask, whole[r0:r0 + h, c0:c0 + w])

