"""View selection of the dense matcher (dense.matching.max_views, issue 21).

Constructed camera sets over a 10 m x 10 m block at z = 0 (cell 0.1 m): the selection keeps
every view when there are no more than the cap, prefers views that see the whole block at a
GSD no coarser than the cell, and spreads the kept rays apart; on a synthetic block a cap
above the view count leaves the surface bit for bit unchanged and a cap below it keeps the
accuracy of tests/dense/test_matching.py.
"""

from __future__ import annotations

from dataclasses import replace
from itertools import combinations

import numpy as np
import pytest

import dense_synthetic as ds
from kitegully import InputError
from kitegully.dense.matching import MatchParams
from kitegully.dense.surface import count_seen, dense_surface
from kitegully.dense.view_selection import select_views, view_geometry
from kitegully.dense.views import ViewSet
from kitegully.io.raster import GridSpec
from kitegully.seeds import rng_for

BOX = (-5.0, -5.0, 5.0, 5.0)
CELL = 0.1


def _cam(name, x, y, h, f=400.0, size=(400, 400)):
    return ds.nadir_view(name, (x, y, h), f=f, width=size[0], height=size[1])


def _angle(a, b):
    return np.degrees(np.arccos(np.clip(a @ b, -1, 1)))


def test_all_views_kept_when_not_more_than_the_cap():
    views = ViewSet([_cam(f"v{i}", 2.0 * i, 0.0, 20.0) for i in range(5)])
    idx = [0, 2, 3, 4]
    for cap in (None, 4, 5, 100):
        assert select_views(views, idx, BOX, 0.0, CELL, cap) == idx
    assert len(select_views(views, idx, BOX, 0.0, CELL, 3)) == 3


def test_prefers_full_coverage_and_fine_gsd():
    # footprint at 20 m: 400 px * 0.05 m = 20 m (whole block); GSD 0.05 m < cell
    full_fine = _cam("full_fine", 0.0, 0.0, 20.0)
    # same height, moved so that it sees about half the block
    half_fine = _cam("half_fine", 10.0, 0.0, 20.0)
    # from 80 m: sees the whole block, GSD 0.2 m = 2 cells (resolution factor 0.5)
    full_coarse = _cam("full_coarse", 0.0, 0.5, 80.0)
    views = ViewSet([half_fine, full_coarse, full_fine])
    seen, q, ray = view_geometry(views, [0, 1, 2], BOX, 0.0, CELL)
    assert seen[2].all() and seen[1].all() and 0.3 < seen[0].mean() < 0.7
    assert q[2] == 1.0 and q[1] == pytest.approx(0.5, rel=0.02)
    assert select_views(views, [0, 1, 2], BOX, 0.0, CELL, 1) == [2]
    # a finer view than the cell gains nothing over one at the cell: both q = 1
    at_cell = _cam("at_cell", 0.0, 0.0, 40.0)
    finer = _cam("finer", 0.0, 0.0, 20.0)
    _, q2, _ = view_geometry(ViewSet([at_cell, finer]), [0, 1], BOX, 0.0, CELL)
    assert q2.tolist() == [1.0, 1.0]


def test_keeps_angular_diversity():
    # a tight cluster of near-duplicate viewpoints over the block (a second flight over the
    # same strip: rays < 3 deg apart) listed first, and three cameras 15-20 m off to the sides
    # (rays 37-45 deg from the cluster); all see the whole block at a GSD finer than the cell
    cluster = [_cam(f"dup{i}", 0.2 * i, 0.1 * i, 20.0, size=(1200, 1200)) for i in range(5)]
    wide = [_cam("east", 15.0, 0.0, 20.0, size=(1200, 1200)), _cam("west", -15.0, 0.0, 20.0, size=(1200, 1200)),
            _cam("north", 0.0, 15.0, 20.0, size=(1200, 1200))]
    views = ViewSet(cluster + wide)
    idx = list(range(8))
    kept = select_views(views, idx, BOX, 0.0, CELL, 4)
    assert len(kept) == 4
    assert {5, 6, 7} <= set(kept), kept            # the three distinct directions
    assert sum(k < 5 for k in kept) == 1, kept    # one nadir view of the cluster
    _, _, ray = view_geometry(views, idx, BOX, 0.0, CELL)
    min_sep = min(_angle(ray[a], ray[b]) for a, b in combinations(kept, 2))
    assert min_sep >= 10.0
    # the first four by index (what a plain truncation would keep) are < 3 deg apart
    assert max(_angle(ray[a], ray[b]) for a, b in combinations(range(4), 2)) < 3.0


def test_max_views_config():
    assert MatchParams.from_config({}).max_views is None
    assert MatchParams.from_config({"max_views": 20}).max_views == 20
    assert MatchParams.from_config({"max_views": None}).max_views is None
    with pytest.raises(InputError, match="dense.matching.max_views: must be null or an integer >= min_views"):
        MatchParams.from_config({"max_views": 1})
    with pytest.raises(InputError, match="dense.matching.max_views"):
        MatchParams.from_config({"max_views": True})
    with pytest.raises(InputError, match="dense.matching.max_views"):
        MatchParams.from_config({"max_views": 3, "min_views": 4})


GSD = 20.0 / 400.0
GRID = GridSpec(-4.0, 4.0, 0.1, 80, 80, "EPSG:32632")
PARAMS = MatchParams(levels=4, window_half_cells=2, z_step_cells=0.5, refine_radius_steps=3, p1=0.02, p2=0.12,
                     sgm_directions=8, min_correlation=0.5)


@pytest.fixture(scope="module")
def slope_block():
    surface = ds.slope()
    views, imgs, _ = ds.block(surface, rng_for(11, "test_view_selection", "slope"))
    xs, ys = GRID.cell_centres()
    return views, imgs, surface(xs[None, :], ys[:, None])


def _surface(block, params):
    views, imgs, _ = block
    return dense_surface(views, GRID, params, tile_cells=96, overlap_cells=16, arrays=imgs)


def test_cap_above_view_count_leaves_the_match_unchanged(slope_block):
    ref = _surface(slope_block, PARAMS)
    capped = _surface(slope_block, replace(PARAMS, max_views=len(slope_block[0].images)))
    np.testing.assert_array_equal(capped.dsm, ref.dsm)
    np.testing.assert_array_equal(capped.ncc, ref.ncc)
    np.testing.assert_array_equal(capped.nviews, ref.nviews)


def test_cap_below_view_count_keeps_accuracy(slope_block):
    views, imgs, truth = slope_block
    ref = _surface(slope_block, PARAMS)
    capped = _surface(slope_block, replace(PARAMS, max_views=5))
    assert ref.nviews.max() > 5 and capped.nviews.max() <= 5
    xs, ys = GRID.cell_centres()
    # cells seen by >= 4 of the 9 views (as test_matching): |mean| <= 0.5 GSD, SD <= 1.5 GSD
    seen = count_seen(views, list(range(len(views.images))), xs, ys, truth) >= 4
    for res in (ref, capped):
        e = (res.dsm - truth)[seen]
        assert np.isfinite(e).mean() > 0.9
        e = e[np.isfinite(e)]
        assert abs(e.mean()) <= 0.5 * GSD and e.std() <= 1.5 * GSD, (e.mean(), e.std())
    assert np.isfinite(capped.dsm).mean() >= np.isfinite(ref.dsm).mean() - 0.05


def test_cache_smaller_than_the_views_warns_and_matches_the_same(slope_block, caplog):
    views, imgs, _ = slope_block
    ref = _surface(slope_block, PARAMS)
    with caplog.at_level("WARNING", logger="kitegully.dense.surface"):
        small = dense_surface(views, GRID, PARAMS, tile_cells=96, overlap_cells=16, max_cached_images=4, arrays=imgs)
    assert "more than the 4 pyramids of dense.max_cached_images" in caplog.text
    np.testing.assert_array_equal(small.dsm, ref.dsm)
    caplog.clear()
    with caplog.at_level("WARNING", logger="kitegully.dense.surface"):
        dense_surface(views, GRID, replace(PARAMS, max_views=4), tile_cells=96, overlap_cells=16, max_cached_images=4,
                      arrays=imgs)
    assert "max_cached_images" not in caplog.text
