"""Kite-scale bare-soil map (kitegully.obia.kite): tiling, global threshold, bad inputs."""

from __future__ import annotations

import numpy as np
import pytest
import rasterio
from scipy import ndimage

from kitegully import InputError
from kitegully.io.raster import GridSpec, read_raster, write_raster
from kitegully.obia.classify import ERODED, GRASS, NODATA
from kitegully.obia.indices import EXG_RANGE, excess_green, gaussian_blur
from kitegully.obia.kite import bare_soil_map
from kitegully.obia.scene import ObiaParams
from kitegully.obia.threshold import find_thresholds

CRS = "EPSG:32632"
CELL = 0.05  # m, a kite orthophoto cell
N = 240  # cells: 12 m x 12 m
PARAMS = ObiaParams()  # the paper's settings (band width 15, sigma 1, radius 2, 5x5 slope)
BANDWIDTH = PARAMS.seed_bandwidth_cells


def _site(seed: int = 3, bare_patches: bool = True):
    """Synthetic orthophoto (8-bit RGB) + DSM of a grass slope with bare patches.

    Grass and soil colours with 8-bit sensor noise (SD 3 DN) and a +-10 % brightness
    field; bare patches are 0.2 m deep hollows in a 20 degree plane.  Returns the grid,
    rgb (3, N, N) uint8, dsm float32 and the truth mask (1 = bare).
    """
    rng = np.random.default_rng(seed)
    grid = GridSpec(500000.0, 4100000.0, CELL, N, N, CRS)
    rows, cols = np.mgrid[0:N, 0:N]
    truth = np.zeros((N, N), dtype=bool)
    if bare_patches:
        for r, c, rad in ((60, 70, 28), (170, 150, 40), (200, 40, 18), (70, 190, 22)):
            truth |= (rows - r) ** 2 + ((cols - c) * 0.8) ** 2 <= rad ** 2
    grass = np.array([60.0, 120.0, 40.0])
    soil = np.array([130.0, 110.0, 90.0])
    field = ndimage.gaussian_filter(rng.standard_normal((N, N)), 20)
    light = 1.0 + 0.1 * field / field.std()
    rgb = np.where(truth[None], soil[:, None, None], grass[:, None, None]) * light[None]
    rgb = np.clip(np.round(rgb + rng.normal(0, 3.0, rgb.shape)), 1, 255).astype(np.uint8)
    dsm = (300.0 - np.tan(np.radians(20)) * cols * CELL - 0.2 * ndimage.gaussian_filter(truth.astype(float), 2)).astype(np.float32)
    return grid, rgb, dsm, truth.astype(np.uint8)


@pytest.fixture(scope="module")
def site_files(tmp_path_factory):
    d = tmp_path_factory.mktemp("kite")
    grid, rgb, dsm, truth = _site()
    write_raster(d / "orthophoto.tif", rgb, grid, nodata=None)
    write_raster(d / "dsm.tif", dsm, grid)
    return d, grid, rgb, dsm, truth


def _run(d, name, tile, ortho="orthophoto.tif", dsm="dsm.tif", params=PARAMS):
    out = d / f"{name}.tif"
    thr = bare_soil_map(d / ortho, d / dsm, out, params, tile)
    classes, grid = read_raster(out)
    return thr, classes, grid


def test_untiled_map_matches_truth_and_global_threshold(site_files):
    d, grid, rgb, dsm, truth = site_files
    thr, classes, out_grid = _run(d, "untiled", tile=N)
    assert out_grid == grid
    assert thr.bimodal and thr.valley is not None
    # the valley lies between the two colours' ExG (soil 0.0, grass 0.64 for these DNs)
    assert excess_green(*[np.array([v]) for v in (130, 110, 90)])[0] < thr.valley < excess_green(*[np.array([v]) for v in (60, 120, 40)])[0]
    # the threshold is that of the whole image's blurred-ExG histogram on the fixed range
    # (two colours: one split, the paper's two-peak valley on hist_bins bins)
    exg = gaussian_blur(excess_green(*rgb.astype(np.float32)), PARAMS.blur_sigma_cells, PARAMS.blur_radius_cells)
    edges = np.linspace(*EXG_RANGE, PARAMS.hist_bins + 1)
    ref = find_thresholds(np.histogram(exg, bins=edges)[0], 0.5 * (edges[1:] + edges[:-1]), PARAMS.min_class_fraction, PARAMS.max_valley_ratio)
    assert thr.valley == pytest.approx(ref.valley, abs=1e-12)
    assert thr.valleys == [thr.valley]
    # pure colours: only segments straddling a patch edge can be wrong, i.e. cells
    # within one seed band width of the edge
    wrong = classes != truth
    edge = ndimage.binary_dilation(truth, iterations=BANDWIDTH) & ~ndimage.binary_erosion(truth, iterations=BANDWIDTH)
    assert not np.any(wrong & ~edge)
    assert wrong.mean() < 0.01


def test_tiled_and_untiled_agree_except_at_tile_borders(site_files):
    d, grid, rgb, dsm, truth = site_files
    thr_full, full, _ = _run(d, "untiled2", tile=N)
    thr_tiled, tiled, _ = _run(d, "tiled", tile=96)  # 3 x 3 tiles, last ones partial
    # the histogram is accumulated over the tile cores, so the threshold is global
    assert thr_tiled.valley == pytest.approx(thr_full.valley, abs=1e-12)
    assert np.array_equal(thr_tiled.counts, thr_full.counts)
    differ = full != tiled
    # segments end at tile borders, so results may differ only where a segment that
    # straddles a class edge is cut: within a band width of both a tile border and an edge
    border = np.zeros((N, N), dtype=bool)
    for b in (96, 192):
        border[max(b - BANDWIDTH, 0): b + BANDWIDTH, :] = True
        border[:, max(b - BANDWIDTH, 0): b + BANDWIDTH] = True
    edge = ndimage.binary_dilation(truth, iterations=BANDWIDTH) & ~ndimage.binary_erosion(truth, iterations=BANDWIDTH)
    assert not np.any(differ & ~(border | edge))
    assert np.mean(tiled == truth) > 0.99


def test_grass_only_site_is_not_forced_into_two_classes(tmp_path):
    grid, rgb, dsm, _ = _site(seed=5, bare_patches=False)
    write_raster(tmp_path / "orthophoto.tif", rgb, grid, nodata=None)
    write_raster(tmp_path / "dsm.tif", dsm, grid)
    thr, classes, _ = _run(tmp_path, "bare", tile=128)
    assert not thr.bimodal and thr.valley is None
    assert np.all(classes == GRASS)


@pytest.mark.parametrize("how", ["mask", "nodata"])
def test_nodata_in_orthophoto_and_dsm_is_nodata_in_the_map(tmp_path, site_files, how):
    _, grid, rgb, dsm, _ = site_files
    rgb = rgb.copy()
    rgb[:, :20, :] = 0  # outside the mosaic
    dsm = dsm.copy()
    dsm[-30:, -30:] = np.nan
    if how == "mask":  # the dense stage's orthophoto: internal mask band, no nodata value
        seen = np.ones(rgb.shape[1:], bool)
        seen[:20] = False
        write_raster(tmp_path / "orthophoto.tif", rgb, grid, mask=seen)
    else:  # an orthophoto from other software: 0 declared as nodata
        write_raster(tmp_path / "orthophoto.tif", rgb, grid, nodata=0)
    write_raster(tmp_path / "dsm.tif", dsm, grid)
    _, classes, _ = _run(tmp_path, "nodata", tile=128)
    assert np.all(classes[:20] == NODATA)
    assert np.all(classes[-30:, -30:] == NODATA)
    assert np.all(np.isin(classes[20:-30], (GRASS, ERODED)))


def test_coarser_dsm_on_another_grid_is_resampled(tmp_path, site_files):
    _, grid, rgb, dsm, truth = site_files
    coarse = GridSpec(grid.x0 - 0.3, grid.y0 + 0.3, 0.2, 66, 66, CRS)  # 20 cm DSM, larger, shifted
    rr, cc = np.mgrid[0:66, 0:66]
    x = coarse.x0 + (cc + 0.5) * 0.2 - grid.x0
    write_raster(tmp_path / "orthophoto.tif", rgb, grid, nodata=None)
    write_raster(tmp_path / "dsm.tif", (300.0 - np.tan(np.radians(20)) * x).astype(np.float32), coarse)
    _, classes, out_grid = _run(tmp_path, "coarse", tile=N)
    assert out_grid == grid
    assert np.mean(classes == truth) > 0.99


@pytest.mark.parametrize(
    "problem, match",
    [
        ("crs", "does not match"),
        ("extent", "does not cover"),
        ("bands", "3 bands"),
        ("missing", "cannot open"),
        ("rotated", "rotated"),
    ],
)
def test_bad_inputs_raise_input_error(tmp_path, site_files, problem, match):
    _, grid, rgb, dsm, _ = site_files
    ortho_grid, dsm_grid, ortho = grid, grid, rgb
    if problem == "crs":
        dsm_grid = GridSpec(grid.x0, grid.y0, grid.cell, N, N, "EPSG:32631")
    elif problem == "extent":
        dsm_grid = GridSpec(grid.x0 + 3.0, grid.y0, grid.cell, N, N, CRS)  # 3 m east: ortho's west strip uncovered
    elif problem == "bands":
        ortho = rgb[:2]
    write_raster(tmp_path / "orthophoto.tif", ortho, ortho_grid, nodata=None)
    write_raster(tmp_path / "dsm.tif", dsm, dsm_grid)
    if problem == "rotated":
        with rasterio.open(tmp_path / "dsm.tif", "r+", IGNORE_COG_LAYOUT_BREAK="YES") as dst:  # products are COGs
            dst.transform = rasterio.Affine(grid.cell, 0.01, grid.x0, 0.01, -grid.cell, grid.y0)
    dsm_name = "nothere.tif" if problem == "missing" else "dsm.tif"
    with pytest.raises(InputError, match=match) as err:
        _run(tmp_path, "bad", tile=N, dsm=dsm_name)
    assert ".tif" in str(err.value)


def _dry_site(seed: int = 11, pond: bool = True, grass=(92.0, 84.0, 56.0)):
    """Orthophoto + DSM of a site with bare soil, grass (default: senescent straw), green shrubs and a pond.

    Reflectances near the twin's palette (x 255): soil (117, 102, 82) ExG 0.02, straw
    (92, 84, 56) ExG 0.09, shrubs (18, 33, 13) ExG 0.55, water (50, 90, 110) ExG 0.08 with
    blue brightest.  Texture: a smooth +-15 % brightness field (sun and shade: ExG does not
    see it) and 3 DN sensor noise.  Returns grid, rgb, dsm and the cover codes
    (0 soil, 1 grass, 2 shrub, 3 water).
    """
    rng = np.random.default_rng(seed)
    grid = GridSpec(500000.0, 4100000.0, CELL, N, N, CRS)
    rows, cols = np.mgrid[0:N, 0:N]
    cover = np.zeros((N, N), dtype=np.uint8)
    cover[:, 120:] = 1
    for r, c, rad in ((40, 200, 14), (120, 170, 18), (200, 215, 16), (190, 140, 10)):
        cover[(rows - r) ** 2 + (cols - c) ** 2 <= rad ** 2] = 2
    if pond:
        cover[(rows - 150) ** 2 + (cols - 50) ** 2 <= 22 ** 2] = 3
    colours = np.array([[117.0, 102.0, 82.0], grass, [18.0, 33.0, 13.0], [50.0, 90.0, 110.0]])
    field = ndimage.gaussian_filter(rng.standard_normal((N, N)), 6)
    light = 1.0 + 0.15 * field / field.std()
    rgb = colours[cover].transpose(2, 0, 1) * light[None]
    rgb = np.clip(np.round(rgb + rng.normal(0, 3.0, rgb.shape)), 1, 255).astype(np.uint8)
    dsm = (300.0 - np.tan(np.radians(5)) * cols * CELL + 0.8 * (cover == 2)).astype(np.float32)
    return grid, rgb, dsm, cover


def _exg(rgb):
    return float(excess_green(*[np.array([v], dtype=np.float32) for v in rgb])[0])


def test_dry_straw_is_mapped_vegetated(tmp_path):
    grid, rgb, dsm, cover = _dry_site(pond=False)
    write_raster(tmp_path / "orthophoto.tif", rgb, grid, nodata=None)
    write_raster(tmp_path / "dsm.tif", dsm, grid)
    thr, classes, _ = _run(tmp_path, "bare", tile=128)
    # the paper's two-peak valley falls between "soil + straw" and shrubs ...
    exg = gaussian_blur(excess_green(*rgb.astype(np.float32)), PARAMS.blur_sigma_cells, PARAMS.blur_radius_cells)
    edges = np.linspace(*EXG_RANGE, PARAMS.hist_bins + 1)
    two = find_thresholds(np.histogram(exg, bins=edges)[0], 0.5 * (edges[1:] + edges[:-1]), PARAMS.min_class_fraction, PARAMS.max_valley_ratio)
    assert two.valley > _exg((92, 84, 56))
    # ... the lowest-mode valley between soil and straw
    assert len(thr.valleys) == 2 and thr.valleys[0] == pytest.approx(two.valley)
    assert _exg((117, 102, 82)) < thr.valley < _exg((92, 84, 56))
    # segments straddling a cover edge may go either way; elsewhere the map is right
    soil = cover == 0
    edge = ndimage.binary_dilation(soil, iterations=BANDWIDTH) & ~ndimage.binary_erosion(soil, iterations=BANDWIDTH)
    wrong = classes != soil
    assert np.mean(wrong & ~edge) < 0.002
    assert np.mean(classes[(cover == 1) & ~edge] == GRASS) > 0.99
    assert np.mean(~wrong) > 0.95


def test_pond_is_left_out_of_the_histogram_and_of_the_map(tmp_path, monkeypatch):
    # green grass site with a pond whose ExG (0.08) lies between soil and grass: below the
    # valley, so mapped bare by ExG alone
    grid, rgb, dsm, cover = _dry_site(pond=True, grass=(26.0, 56.0, 18.0))
    write_raster(tmp_path / "orthophoto.tif", rgb, grid, nodata=None)
    write_raster(tmp_path / "dsm.tif", dsm, grid)
    thr, classes, _ = _run(tmp_path, "bare", tile=128)
    assert len(thr.valleys) == 1 and thr.valley > 0.2
    land = cover != 3
    assert np.mean(classes[land] == (cover[land] == 0)) > 0.95
    # the pond (ExG below the valley: "bare" by ExG alone) is not classified, and counted
    pond = cover == 3
    assert np.mean(classes[pond] == NODATA) > 0.97 and np.mean(classes[land] == NODATA) < 0.005
    assert thr.water_cells == pytest.approx(pond.sum(), rel=0.05)
    import kitegully.obia.kite as kite

    # without the rule the pond (ExG 0.08, eight one-DN steps above soil) is mapped as bare soil
    monkeypatch.setattr(kite, "blue_dominant", lambda r, g, b: np.zeros(np.shape(r), dtype=bool))
    thr_all, classes_all, _ = _run(tmp_path, "bare_all", tile=128)
    assert thr_all.valley > _exg((50, 90, 110)) and np.mean(classes_all[pond] == 1) > 0.97


@pytest.mark.parametrize("index, name", [("exg", "ExG"), ("ndvi", "NDVI")])
def test_map_figure_names_the_thresholded_index(site_files, index, name):
    from kitegully.obia import kite_map_figure

    d = site_files[0]
    thr, classes, grid = _run(d, f"figure_{index}", N)
    fig = kite_map_figure(d / "orthophoto.tif", classes, grid, thr, 200, index)
    assert fig.axes[2].get_xlabel() == f"{name}, Gaussian-blurred (-)"
    assert fig.axes[1].get_legend().get_texts()[0].get_text() == f"bare soil ({name} below the valley)"


def test_scattered_blue_cells_do_not_unclassify_land(tmp_path, site_files):
    # one cell in five of the grass made blue-brightest (glints, sky reflections): a segment is
    # left unclassified only when most of its cells are blue-dominant
    d, grid, rgb, dsm, truth = site_files
    rng = np.random.default_rng(5)
    spots = (rng.random(truth.shape) < 0.2) & (truth == 0)
    speckled = rgb.copy()
    speckled[:, spots] = np.array([60, 110, 125], np.uint8)[:, None]
    write_raster(tmp_path / "orthophoto.tif", speckled, grid, nodata=None)
    write_raster(tmp_path / "dsm.tif", dsm, grid)
    thr, classes, _ = _run(tmp_path, "speckled", tile=N)
    assert np.mean(classes == NODATA) < 0.005 and thr.water_cells < 0.005 * truth.size

