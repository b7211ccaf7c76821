"""Dense matching on synthetic views of analytic surfaces (plane, slope, step).

Geometry of the test block (tests/dense_synthetic.py): 3 × 3 nadir views (±2° tilt) from
20 m above ground, f = 400 px → GSD = 0.05 m; bases 3–4 m (H/B ≈ 3.6 over the pairs).
The DSM cell is 0.1 m (2 GSD). A matching precision of ~0.2 px gives an elevation
precision of 0.2 px · GSD · H/B ≈ 0.04 m, so the stated tolerances are the issue's target:
|mean| ≤ 0.5 GSD and SD ≤ 1.5 GSD, on cells seen by ≥ 4 images (the corners of this
small block are seen by 2 images 4 m apart only, with H/B = 5 there).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

import dense_synthetic as ds
from kitegully import InputError
from kitegully.dense.kernels import multiview_ncc_stack, occlusion_mask
from kitegully.dense.matching import MatchParams, equal_significance_correlation
from kitegully.dense.ortho import orthophoto
from kitegully.dense.shading import openness
from kitegully.dense.surface import count_seen, dense_surface, tile_z_range
from kitegully.dense.views import PyramidCache, ViewSet, load_image, views_from_reconstruction
from kitegully.io.raster import GridSpec
from kitegully.seeds import rng_for
from kitegully.terrain.shading import hillshade

GSD = 20.0 / 400.0
CELL = 0.1
GRID = GridSpec(-8.0, 8.0, CELL, 160, 160, "EPSG:32632")
PARAMS = MatchParams(levels=4, window_half_cells=2, z_step_cells=0.5, refine_radius_steps=3, p1=0.02, p2=0.12,
                     sgm_directions=8, min_correlation=0.5)


def _run(surface, name, grid=GRID):
    views, imgs, tex = ds.block(surface, rng_for(11, "test_dense", name))
    res = dense_surface(views, grid, PARAMS, tile_cells=96, overlap_cells=16, arrays=imgs)
    xs, ys = grid.cell_centres()
    truth = surface(xs[None, :], ys[:, None])
    seen_true = count_seen(views, list(range(len(views.images))), xs, ys, truth)
    return views, imgs, tex, res, truth, seen_true


@pytest.fixture(scope="module")
def plane_case():
    return _run(ds.plane(), "plane")


@pytest.fixture(scope="module")
def step_case():
    return _run(ds.step(height=1.5), "step")


def _check_accuracy(res, truth, mask):
    e = (res.dsm - truth)[mask]
    e = e[np.isfinite(e)]
    assert e.size > 0.9 * mask.sum()
    assert abs(e.mean()) <= 0.5 * GSD, e.mean()
    assert e.std() <= 1.5 * GSD, e.std()


def test_plane_recovered(plane_case):
    _, _, _, res, truth, seen = plane_case
    _check_accuracy(res, truth, seen >= 4)
    assert res.coverage() >= 0.95


def test_slope_recovered():
    _, _, _, res, truth, seen = _run(ds.slope(gx=0.3, gy=-0.15), "slope")
    _check_accuracy(res, truth, seen >= 4)
    assert res.coverage() >= 0.95


def test_step_recovered(step_case):
    _, _, _, res, truth, seen = step_case
    xs, _ = GRID.cell_centres()
    # exclude the wall: correlation window (±0.25 m) plus SGM smoothing across the edge
    away = np.broadcast_to(np.abs(xs)[None, :] > 0.6, truth.shape)
    _check_accuracy(res, truth, (seen >= 4) & away)
    low = np.nanmedian(res.dsm[:, (xs < -0.6) & (xs > -4)])
    high = np.nanmedian(res.dsm[:, (xs > 0.6) & (xs < 4)])
    assert abs((high - low) - 1.5) <= 2 * GSD


def test_tile_z_range_covers_sloped_tile():
    """Tie points only in the low half of a tile on a 20 % slope: the elevation range must
    still reach the tile's high corner (the default twin's valley sides lost whole tile
    strips to this before the plane fit)."""
    rng = rng_for(11, "test_dense", "zrange")
    gx, gy, margin = 0.2, 0.1, 1.0
    xy = rng.uniform([0.0, 0.0], [64.0, 20.0], size=(200, 2))  # the tile is 64 m x 64 m
    z = 100.0 + gx * xy[:, 0] + gy * xy[:, 1] + rng.normal(0.0, 0.05, 200)
    far = np.array([[500.0, 500.0, 80.0], [-500.0, -500.0, 140.0]])  # the site's relief elsewhere
    views = ViewSet([], np.zeros(3), np.vstack([np.column_stack([xy, z]), far]))
    lo, hi = tile_z_range(views, (0.0, 0.0, 64.0, 64.0), margin)
    corners = 100.0 + gx * np.array([0, 64, 0, 64]) + gy * np.array([0, 0, 64, 64])
    assert lo <= corners.min() - margin + 0.2 and hi >= corners.max() + margin - 0.2  # 0.2 m: noise percentiles
    # the fit does not widen the range beyond the relief of all tie points
    lo2, hi2 = tile_z_range(ViewSet([], np.zeros(3), np.column_stack([xy, z])), (0.0, 0.0, 64.0, 64.0), margin)
    assert hi2 <= z.max() + margin + 1e-9


@pytest.fixture(scope="module")
def pillar_case():
    surf = ds.pillars(height=3.0, radius=1.0)
    views, imgs, _ = ds.block(surf, rng_for(11, "test_dense", "pillars"))
    xs, ys = GRID.cell_centres()
    truth = surf(xs[None, :], ys[:, None])
    seen = count_seen(views, list(range(len(views.images))), xs, ys, truth)
    d = np.min([np.hypot(xs[None, :] - cx, ys[:, None] - cy) for cx, cy in surf.centres], axis=0)
    out = {}
    for passes in (1, 2):
        p = MatchParams(**{**PARAMS.__dict__, "final_passes": passes})
        out[passes] = dense_surface(views, GRID, p, tile_cells=96, overlap_cells=16, arrays=imgs)
    return out, truth, seen, d, surf.radius


def test_final_pass_recovers_what_the_coarse_prior_misses(pillar_case):
    """3 m pillars 2 m wide: the 0.8 m coarse cells (4 m windows) smear them, and the ±3-step
    refine windows of the finer levels miss their tops. A second level-0 pass around the
    level-0 surface finds them, without adding wrong cells (|error| > 3 GSD) away from the
    walls (where any window matcher fattens edges: window half-size 0.2 m + 2 cells)."""
    out, truth, seen, d, radius = pillar_case
    tops = (d < radius - 0.3) & (seen >= 4)  # away from the wall by more than the window half-size
    right = {k: np.isfinite(r.dsm) & (np.abs(r.dsm - truth) < 3 * GSD) for k, r in out.items()}
    off_wall = (seen >= 4) & (np.abs(d - radius) > 0.4)
    wrong = {k: (np.isfinite(r.dsm) & ~right[k])[off_wall].sum() for k, r in out.items()}
    assert right[2][tops].mean() >= 0.9
    assert right[2][tops].mean() >= right[1][tops].mean() + 0.05
    assert wrong[2] <= wrong[1]
    assert out[2].coverage() > out[1].coverage()
    # away from the walls the recovered surface meets the accuracy target
    flat = (seen >= 4) & ((d > radius + 0.6) | (d < radius - 0.6))
    _check_accuracy(out[2], truth, flat)


def test_texture_threshold_per_view():
    """The texture test takes one threshold per view (``min_std_dn / 2**level`` for a view
    sampled at pyramid level ``level``: 2x2 means halve the noise SD per level). Windows of
    SD 1.5 DN pass a threshold of 1 DN and fail one of 2 DN."""
    rng = rng_for(11, "test_dense", "texture-threshold")
    base = rng.normal(0.0, 1.0, (7, 7))
    a = 100.0 + 1.5 * (base - base[1:6, 1:6].mean()) / base[1:6, 1:6].std()  # centre window SD 1.5 DN
    stack = np.stack([a, a, a])[None].astype(np.float32)  # K=1, V=3, 7x7 cells
    score = np.empty((1, 7, 7), np.float32)
    nv = np.empty((1, 7, 7), np.int16)
    multiview_ncc_stack(stack, 2, np.array([1.0, 1.0, 2.0]), score, nv)
    assert nv[0, 3, 3] == 2 and score[0, 3, 3] == pytest.approx(1.0, abs=1e-3)  # float32 window sums
    multiview_ncc_stack(stack, 2, np.array([2.0, 1.0, 2.0]), score, nv)
    assert nv[0, 3, 3] == 1 and np.isnan(score[0, 3, 3])


def test_unseen_cells_masked():
    """Cells outside the footprints or seen by a single image get no elevation."""
    big = GridSpec(-16.0, 16.0, 0.2, 160, 160, "EPSG:32632")
    _, _, _, res, truth, seen = _run(ds.plane(), "plane-big", grid=big)
    assert (seen < 2).sum() > 1000  # the grid really extends beyond the block
    valid = np.isfinite(res.dsm)
    # every valid cell is seen by >= 2 images at its own elevation
    assert (res.nseen[valid] >= 2).all()
    # a surface found dz too low widens the footprints by dz * tan(edge angle); with
    # |dz| <= z_margin (2 m) and tan = 8 m / 20 m that is <= 0.8 m = 4 cells of 0.2 m
    dist = ndimage.distance_transform_edt(seen < 2)
    assert not (valid & (dist > 4)).any()
    assert (valid & (seen < 2)).sum() < 0.01 * (seen >= 2).sum()
    # away from the coverage edge (3 cells = window half-size + 1) nearly every cell is valid
    inner = ndimage.binary_erosion(seen >= 4, iterations=3)
    assert valid[inner].mean() > 0.95


def test_orthophoto_matches_texture(plane_case):
    views, imgs, tex, res, truth, seen = plane_case
    img, og, src = orthophoto(views, res.dsm, GRID, upsample=2, tile_cells=64, arrays=imgs)
    assert og.cell == pytest.approx(CELL / 2)
    xs, ys = og.cell_centres()
    ref = tex(*np.meshgrid(xs, ys))
    m = (src >= 0) & np.broadcast_to(np.hypot(xs[None, :], ys[:, None]) < 6, src.shape)
    d = img[0][m].astype(float) - ref[m]
    # the texture has detail at the pixel scale: allow the pixel-averaging blur, not misplacement
    assert np.corrcoef(img[0][m], ref[m])[0, 1] > 0.9
    assert abs(d.mean()) < 3.0
    # the chosen image is the most nadir one: the centre cell comes from the centre view
    assert views.images[src[src.shape[0] // 2, src.shape[1] // 2]].name == "v11"


def test_occlusion_mask_wall():
    dsm = np.zeros((50, 50))
    dsm[:, 30:32] = 10.0  # a 10 m wall at x = 30–32 m
    xs = np.array([20.0, 40.0])
    ys = np.array([25.0])
    Z = np.zeros((1, 2))
    out = np.empty((1, 2), bool)
    occlusion_mask(dsm, 0.0, 50.0, 1.0, 10.0, xs, ys, Z, np.array([45.0, 25.0, 20.0]), 0.5, 0.1, out)
    assert out.tolist() == [[True, False]]


def test_shading_plane_and_trench():
    z = np.zeros((40, 40))
    assert np.allclose(hillshade(z, 0.5, altitude_deg=45), np.sin(np.radians(45)))
    assert np.allclose(openness(z, 0.5, 5.0), 90.0)
    zt = z.copy()
    zt[:, 18:22] = -2.0
    o = openness(zt, 0.5, 5.0)
    assert o[20, 20] < 70 and np.isclose(o[20, 5], 90.0)


def test_pycolmap_reader(tmp_path):
    pycolmap = pytest.importorskip("pycolmap")
    rec = pycolmap.Reconstruction()
    cam = pycolmap.Camera.create_from_model_name(1, "SIMPLE_RADIAL", 400.0, 320, 240)
    cam.params = [400.0, 159.5, 119.5, 0.01]
    rec.add_camera_with_trivial_rig(cam)
    views = [ds.nadir_view("a.png", (578000.0, 4081000.0, 150.0)), ds.nadir_view("b.png", (578004.0, 4081000.0, 150.0))]
    model_off = np.array([578000.0, 4081000.0, 0.0])
    for k, v in enumerate(views, start=1):
        img = pycolmap.Image(name=v.name, camera_id=1, image_id=k)
        t = -v.R @ (v.C - model_off)
        rec.add_image_with_trivial_frame(img, pycolmap.Rigid3d(pycolmap.Rotation3d(v.R), t))
    rec.add_point3D(np.array([1.0, 2.0, 130.0]), pycolmap.Track())
    vs = views_from_reconstruction(rec, tmp_path, model_offset=model_off)
    assert len(vs.images) == 2 and vs.images[0].k1 == pytest.approx(0.01)
    assert np.allclose(vs.images[1].C + vs.offset, views[1].C, atol=1e-6)
    assert np.allclose(vs.sparse_points[0] + vs.offset, [578001.0, 4081002.0, 130.0])
    assert np.abs(vs.images[0].C[:2]).max() < 10  # local coordinates are small
    X = np.array([578002.0, 4081001.0, 100.0]) - vs.offset
    u, v, _ = vs.images[0].project(X)
    assert 0 < u < 320 and 0 < v < 240
    with pytest.raises(InputError, match="image file not found"):
        PyramidCache(vs).level(0, 0)


def test_bad_inputs(tmp_path):
    bad = tmp_path / "x.png"
    bad.write_bytes(b"not an image")
    with pytest.raises(InputError, match="x.png"):
        load_image(bad)
    pycolmap = pytest.importorskip("pycolmap")
    rec = pycolmap.Reconstruction()
    with pytest.raises(InputError, match="at least two"):
        views_from_reconstruction(rec, tmp_path, where="georef/model")
    with pytest.raises(InputError, match="tie points"):
        dense_surface(ViewSet([ds.nadir_view("a", (0, 0, 20)), ds.nadir_view("b", (2, 0, 20))]), GRID, PARAMS)
    with pytest.raises(InputError, match="sgm_directions"):
        MatchParams.from_config({"sgm_directions": 6})
    with pytest.raises(InputError, match="final_passes"):
        MatchParams.from_config({"final_passes": 0})


def test_a_narrower_final_window_resolves_narrow_trenches():
    """0.4 m wide, 0.5 m deep trenches (8 GSD wide; a 5 x 5-cell window spans 0.5 m): the last
    level-0 pass with a 3 x 3 window (0.3 m) finds more of their floor than the 5 x 5 window,
    the plane between them keeps the issue's accuracy, and no cell is lost."""
    surf = ds.trench(depth=0.5, width=0.4)
    views, imgs, _ = ds.block(surf, rng_for(11, "test_dense", "trench"))
    xs, ys = GRID.cell_centres()
    truth = surf(xs[None, :], ys[:, None])
    seen = count_seen(views, list(range(len(views.images))), xs, ys, truth)
    d = np.min([np.abs(xs[None, :] - cx) for cx in surf.x_centres], axis=0) + 0.0 * ys[:, None]
    floor = (d < 0.1) & (seen >= 4)  # the trench's middle cells (two of its four cells across)
    out = {}
    for half in (2, 1):
        # min_correlation 0.3 as on the Kamech sites (narrow pass 0.52); with this file's 0.5 the
        # narrow pass needs 0.87 and most floor cells keep the 5 x 5 value (0.39 vs 0.36 m)
        p = MatchParams(**{**PARAMS.__dict__, "final_passes": 2, "final_window_half_cells": half,
                           "min_correlation": 0.3})
        out[half] = dense_surface(views, GRID, p, tile_cells=96, overlap_cells=16, arrays=imgs)
    depth = {h: np.nanmedian(100.0 - r.dsm[floor]) for h, r in out.items()}
    assert depth[1] >= depth[2] + 0.03, depth  # measured 0.41 vs 0.36 m of the 0.5 m
    plane_cells = (seen >= 4) & (d > 0.6)
    _check_accuracy(out[1], truth, plane_cells)
    # where the 3 x 3 window fails its texture or correlation test the 5 x 5 pass's cell stands
    assert out[1].coverage() >= out[2].coverage()
    with pytest.raises(InputError, match="final_window_half_cells"):
        MatchParams.from_config({"final_window_half_cells": -1})


def test_the_narrow_window_threshold_passes_noise_as_rarely_as_the_wide_one():
    """NCC of pure-noise windows: 3 x 3 windows pass the scaled threshold about as often as 5 x 5
    windows pass min_correlation (0.3: 7.3 vs 7.7 % measured), and three times as often unscaled."""
    rng = np.random.default_rng(5)

    def share_above(n: int, t: float) -> float:
        a, b = rng.normal(size=(2, 100_000, n))
        a -= a.mean(axis=1, keepdims=True)
        b -= b.mean(axis=1, keepdims=True)
        r = (a * b).sum(axis=1) / np.sqrt((a * a).sum(axis=1) * (b * b).sum(axis=1))
        return float((r >= t).mean())

    t_narrow = equal_significance_correlation(0.3, half_wide=2, half_narrow=1)
    assert t_narrow == pytest.approx(0.3 * np.sqrt(24 / 8))
    wide, narrow, unscaled = share_above(25, 0.3), share_above(9, t_narrow), share_above(9, 0.3)
    assert narrow == pytest.approx(wide, rel=0.2)
    assert unscaled > 2.5 * wide
    assert equal_significance_correlation(0.4, 2, 2) == pytest.approx(0.4)
