"""The gully stage's table and raster helpers beside map_gullies (kitegully.gully.pipeline), and
the sensitivity entry point (kitegully.gully.sensitivity.gully_sensitivity)."""

from __future__ import annotations

import geopandas as gpd
import numpy as np
import pytest
from shapely import LineString

from kitegully.evaluate.network import footprint
from kitegully.gully.network import network_lines
from kitegully.gully.params import GullyParams
from kitegully.gully.pipeline import gully_summary, map_gullies, map_raster
from kitegully.gully.sensitivity import gully_sensitivity, sensitivity_table
from kitegully.io.raster import GridSpec

CRS = "EPSG:32632"


def test_map_raster_codes():
    valid = np.array([[True, True, False]])
    out = map_raster(np.array([[True, False, True]]), valid)
    assert out.dtype == np.uint8 and out.tolist() == [[1, 0, 255]]


def test_gully_summary_reports_the_run(mapped):
    grid, _, params, res = mapped
    table = gully_summary(res, grid, params, "dense", n_heads=3)
    assert list(table.columns) == ["quantity", "value"] and table["value"].map(type).eq(str).all()
    v = dict(table.values)
    assert v["DEM source"] == "dense" and v["gully heads"] == "3" and v["heads on the DEM"] == "1"
    assert v["DEM cells"] == str(300 * 200) and v["cell size (m)"] == "0.5"
    assert v["head snapping"] == "lowest cell within 2.0 m"
    assert float(v["gully area (m2)"]) == pytest.approx(round(float(res.polygons["area_m2"].sum()), 1))
    assert float(v["traced network length (m)"]) > 100  # the gully runs ~135 m to the east edge
    assert v["paths ending in a pit"] == "0"
    assert [q for q in v if q.startswith("time ")] == [f"time {k[:-2]} (s)" for k in res.timings_s]


def test_gully_sensitivity_is_the_table_with_the_stage_settings(mapped):
    grid, z, params, res = mapped
    xs, ys = grid.cell_centres()
    yc = ys[grid.height // 2]
    reference = gpd.GeoDataFrame(geometry=[LineString([(xs[30], yc + 0.4), (xs[-1], yc + 0.4)])], crs=CRS)
    got = gully_sensitivity(z, grid, res.network, res.depth, params, [5.0, 8.0], [0.25], 5.0, reference=reference)
    domain = footprint(np.isfinite(z), grid, near=[*reference.geometry, *network_lines(res.network, grid).geometry])
    expected = sensitivity_table(z, grid, res.network, [5.0, 8.0], [0.25], params.min_patch_volume_m3, params.buffer_m,
                                 params.connectivity, params.truncate_sigmas, reference=reference, tolerance_m=5.0,
                                 domain=domain)
    assert got.equals(expected)
    # the stage's own depth map is reused at sigma_m: same row as recomputing it
    row = got[got["sigma_m"] == 5.0].iloc[0]
    assert row["gully_area_m2"] == pytest.approx(float(res.gully.sum()) * grid.cell**2)
    assert row["good_fit_percent"] > 90


def test_two_workers_give_the_same_products(mapped):
    """With 2 workers the fill branch runs beside the depth map and the sensitivity's depth
    maps are smoothed in a second thread (issue 21): the products are the same."""
    grid, z, params, res1 = mapped
    xs, ys = grid.cell_centres()
    yc = ys[grid.height // 2]
    res2 = map_gullies(z, grid, np.array([xs[30]]), np.array([yc]), params, workers=2)
    for name in ("depth", "smoothed", "patch_labels", "gully", "gully_whole_patches"):
        assert np.array_equal(getattr(res1, name), getattr(res2, name), equal_nan=True), name
    assert np.array_equal(res1.network.cells, res2.network.cells) and res1.n_raised == res2.n_raised
    assert res1.n_flat_routed == res2.n_flat_routed and res1.polygons.equals(res2.polygons)
    assert {"fill_s", "fill_branch_s"} <= set(res2.timings_s)
    # σ not in order and one of them known: rows keep the order asked for
    args = (z, grid, res1.network, [8.0, 5.0, 6.0], [0.25, 0.5], 1.0, 15.0, 8, 4.0)
    t1 = sensitivity_table(*args, workers=1, known_depths={5.0: res1.depth})
    t2 = sensitivity_table(*args, workers=2, known_depths={5.0: res1.depth})
    assert t1.equals(t2) and t1["sigma_m"].tolist() == [8.0, 8.0, 5.0, 5.0, 6.0, 6.0]
    assert t1["gully_area_m2"].nunique() > 1


@pytest.mark.parametrize("workers", [1, 2])
def test_on_depth_gets_the_depth_rasters_before_the_fill_is_waited_for(mapped, workers):
    """``on_depth`` (the rule writes the depth rasters there, beside the fill) gets the
    result's own smoothed and depth arrays, once, and the products do not change."""
    grid, z, params, res1 = mapped
    xs, ys = grid.cell_centres()
    seen = []
    res = map_gullies(z, grid, np.array([xs[30]]), np.array([ys[grid.height // 2]]), params, workers=workers,
                      on_depth=lambda s, d: seen.append((s, d)))
    assert len(seen) == 1 and seen[0][0] is res.smoothed and seen[0][1] is res.depth
    assert np.array_equal(res.depth, res1.depth, equal_nan=True) and np.array_equal(res.gully, res1.gully)
    assert "on_depth_s" in res.timings_s


def test_depth_map_is_the_same_on_one_or_several_fft_threads(mapped):
    """The sensitivity's parallel depth maps run their FFTs on one thread each: the values
    are those of one smoothing on several threads (the rule's former way), bit for bit."""
    from kitegully.gully.depth import depth_map

    _, z, _, _ = mapped
    for sigma in (1.0, 7.5):
        one, two = depth_map(z, 0.5, sigma, 4.0, 1), depth_map(z, 0.5, sigma, 4.0, 3)
        assert all(np.array_equal(a, b, equal_nan=True) for a, b in zip(one, two))


def test_sensitivity_domain_may_be_made_beside_the_depth_maps(mapped):
    """A callable domain (made once the depth maps have started) gives the table of the domain itself."""
    grid, z, params, res = mapped
    xs, ys = grid.cell_centres()
    yc = ys[grid.height // 2]
    reference = gpd.GeoDataFrame(geometry=[LineString([(xs[30], yc + 0.4), (xs[-1], yc + 0.4)])], crs=CRS)
    domain = footprint(np.isfinite(z), grid, near=[*reference.geometry, *network_lines(res.network, grid).geometry])
    calls = []

    def make():
        calls.append(1)
        return domain

    args = (z, grid, res.network, [5.0, 8.0, 3.0], [0.25], 1.0, 15.0, 8, 4.0)
    for workers in (1, 2):
        got = sensitivity_table(*args, reference=reference, domain=make, workers=workers, known_depths={5.0: res.depth})
        assert got.equals(sensitivity_table(*args, reference=reference, domain=domain, workers=1,
                                            known_depths={5.0: res.depth}))
    assert len(calls) == 2


def test_both_heads_also_map_the_given_heads_alone_as_digitised_heads_would():
    # two channels in two hollows of a 10 % slope; the operator digitised the western head only.
    # gully.heads: both traces the detector's head on the eastern channel too, and its
    # given_extracted_lines are exactly the network that gully.heads: digitised maps on the same DEM
    from kitegully.gully.heads import HeadDetectionParams

    p = HeadDetectionParams(scale_m=2.0, relief_k=3.0, dsm_sigma_z_m=0.05, slope_window_m=1.0, area_slope_a=0.025,
                            area_slope_b=0.4, min_channel_length_m=10.0)
    n, cell = 400, 0.2
    grid = GridSpec(0.0, n * cell, cell, n, n, CRS)
    xs, ys = grid.cell_centres()
    X, Y = np.meshgrid(xs, ys)
    dx = np.minimum(np.abs(X - 20.0), np.abs(X - 60.0))
    channel = 0.8 * np.clip(1 - dx, 0, None) * np.clip((60.0 - Y) / 0.4, 0, 1)
    z = (0.1 * Y + 0.05 * dx - channel + np.random.default_rng(0).normal(0, 0.01, X.shape)).astype(np.float32)
    params = GullyParams(sigma_m=3.0, head_snap_radius_m=6.0)
    hx, hy = np.array([20.0]), np.array([59.0])
    both = map_gullies(z, grid, hx, hy, params, workers=1, auto_heads=p, incision=p)
    digitised = map_gullies(z, grid, hx, hy, params, workers=1, incision=p)
    assert both.auto_heads.size == 1 and abs(xs[both.auto_heads[0] % n] - 60.0) < 1.0  # the head nobody digitised
    east = both.extracted_lines.geometry.bounds["minx"] > 50.0
    assert east.any() and both.extracted_lines[east].length.sum() > 40.0
    alone = both.given_extracted_lines
    assert (alone.geometry.bounds["maxx"] < 30.0).all() and alone.length.sum() > 40.0
    assert alone.geometry.union_all().equals(digitised.extracted_lines.geometry.union_all())
    assert digitised.given_extracted_lines is None  # nothing to separate without automatic heads
