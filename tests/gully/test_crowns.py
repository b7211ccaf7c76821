"""Gullies under shrub crowns (gully.crowns, issue 15): crown mask, tracing under it, hidden-reach bridges."""

from __future__ import annotations

import numpy as np
import pytest

from kitegully import InputError
from kitegully.gully.crowns import CrownParams, crown_mask, excess_green, green_threshold, hidden_reaches, interpolate_under
from kitegully.gully.heads import HeadDetectionParams
from kitegully.gully.params import GullyParams
from kitegully.gully.pipeline import map_gullies
from kitegully.io.raster import GridSpec

CELL = 0.2
NX, NY = 400, 200  # 80 m downslope (x), 40 m across (y)
YC = 20.0  # channel centreline (m)
IP = HeadDetectionParams(scale_m=2.0, relief_k=3.0, dsm_sigma_z_m=0.05, slope_window_m=1.0, area_slope_a=0.025,
                         area_slope_b=0.4, min_channel_length_m=10.0)
SOIL = np.array([120.0, 110.0, 95.0])
FOLIAGE = np.array([40.0, 90.0, 30.0])


def _grid():
    return GridSpec(x0=0.0, y0=NY * CELL, cell=CELL, width=NX, height=NY, crs="EPSG:32632")


def channel_with_shrubs(shrubs_x=(30.0, 42.0), green_flat=False):
    """A 10 % plane draining towards +x, a 1 m wide, 0.5 m deep channel along y = YC from x = 5 m.

    Shrubs 1 m high line both banks (0.5–2.5 m from the centreline) for x in ``shrubs_x``; the
    DSM over the channel between them stands at the crowns' height (the matching window's
    foreground fattening), a 1 m dam. Three shrub clumps also stand on the field (y = 6 m). The
    orthophoto is soil-coloured with colour noise, green on the crowns (not over the channel
    floor); ``green_flat`` adds a green but flat grass plot (y 30–38 m), green without height.
    """
    grid = _grid()
    xs, ys = grid.cell_centres()
    X, Y = np.meshgrid(xs, ys)
    ground = -0.1 * X
    d = np.abs(Y - YC)
    chan = (X >= 5.0) & (d <= 0.5)
    ground = ground - np.where(chan, 0.5, 0.0)
    z = ground.copy()
    x0, x1 = shrubs_x
    along = (X >= x0) & (X <= x1)
    crowns = along & (d > 0.5) & (d <= 2.5)
    z = np.where(crowns, -0.1 * X + 1.0, z)
    z = np.where(along & (d <= 0.5), -0.1 * X + 1.0, z)  # the crowns' height over the narrow floor
    field = np.zeros_like(crowns)
    for cx in (15.0, 40.0, 65.0):
        field |= (np.abs(X - cx) <= 1.5) & (np.abs(Y - 6.0) <= 1.5)
    z = np.where(field, -0.1 * X + 1.0, z)
    rng = np.random.default_rng(7)
    rgb = SOIL[:, None, None] + rng.normal(0.0, 3.0, (3, NY, NX))
    green = crowns | field
    if green_flat:
        green = green | ((Y >= 30.0) & (Y <= 38.0) & (X >= 10.0) & (X <= 70.0))
    rgb = np.where(green[None], FOLIAGE[:, None, None] + rng.normal(0.0, 3.0, (3, NY, NX)), rgb)
    return grid, z.astype(np.float32), rgb.astype(np.float32), xs, ys


def _params(enabled: bool, bridge_max_m=None):
    return GullyParams(sigma_m=6.0, head_snap="lowest", head_snap_radius_m=0.5, trace_smoothing_m=0.5,
                       water_min_area_m2=None, crowns=CrownParams(enabled=enabled, bridge_max_m=bridge_max_m))


def _path_offsets(res, grid, ys, xs, x_from):
    r, c = np.divmod(res.network.cells, grid.width)
    sel = xs[c] >= x_from
    return np.abs(ys[r][sel] - YC)


def test_path_stays_in_the_channel_under_the_shrubs_and_the_hidden_reach_counts_as_mapped():
    grid, z, rgb, xs, ys = channel_with_shrubs()
    hx, hy = np.array([6.0]), np.array([YC])
    off = map_gullies(z, grid, hx, hy, _params(False), incision=IP)
    on = map_gullies(z, grid, hx, hy, _params(True), incision=IP, ortho=rgb)
    # on the DSM the shrub dam sends the path down the field beside the channel, and it never returns
    assert _path_offsets(off, grid, ys, xs, 45.0).max() > 2.0
    # under the crowns the surface is interpolated from the channel up- and downstream: it stays in the channel
    assert _path_offsets(on, grid, ys, xs, 5.0).max() <= 1.0
    assert on.crowns is not None and on.crowns[np.abs(ys - YC) <= 0.5][:, (xs > 31) & (xs < 41)].all()
    # the reach under the crowns has no depth patch; bridged, it counts as mapped
    assert on.bridged.sum() * CELL >= 10.0
    r, c = np.divmod(np.flatnonzero(on.bridged), grid.width)
    assert (xs[c].min() >= 28.0) and (xs[c].max() <= 44.0)
    mapped_on = on.extracted_lines["length_m"].sum()
    assert mapped_on >= 0.9 * (xs[-1] - 6.0)
    assert mapped_on > on.lines["length_m"].sum() - 2.0


def test_no_bridge_without_a_mapped_reach_downstream_and_green_flat_grass_is_no_crown():
    # shrubs down to the DEM edge: the reach under them leads to no mapped reach, so it is not bridged
    grid, z, rgb, xs, ys = channel_with_shrubs(shrubs_x=(64.0, 80.0), green_flat=True)
    res = map_gullies(z, grid, np.array([6.0]), np.array([YC]), _params(True), incision=IP, ortho=rgb)
    assert res.crowns[np.abs(ys - YC) <= 0.5][:, xs > 66.0].all()
    assert res.bridged.sum() == 0
    # the green grass plot stands on the ground: no crown there (away from its edges)
    Y = ys[:, None] * np.ones((1, NX))
    X = xs[None, :] * np.ones((NY, 1))
    inner = (Y >= 31.5) & (Y <= 36.5) & (X >= 12.0) & (X <= 68.0)
    assert not res.crowns[inner].any()
    # a cap shorter than the hidden reach leaves it unmapped
    grid, z, rgb, xs, ys = channel_with_shrubs()
    capped = map_gullies(z, grid, np.array([6.0]), np.array([YC]), _params(True, bridge_max_m=5.0), incision=IP,
                         ortho=rgb)
    assert capped.bridged.sum() == 0



def test_a_tiled_site_traces_and_bridges_under_the_same_crowns():
    """The tiled path (crown mask and surface in one job, tiled fill, the map given both) equals the untiled map."""
    from kitegully.gully.surface import crowns_on, tracing_surface
    from kitegully.terrain.tiled_fill import tiled_priority_flood_fill

    grid, z, rgb, xs, ys = channel_with_shrubs()
    hx, hy = np.array([6.0]), np.array([YC])
    params = _params(True)
    ref = map_gullies(z, grid, hx, hy, params, incision=IP, ortho=rgb)
    hidden = crowns_on(z, grid, params, IP, rgb)
    _, z_trace, _ = tracing_surface(z, grid, params, incision=IP, hidden=hidden)
    filled = tiled_priority_flood_fill(z_trace, 37)
    got = map_gullies(z, grid, hx, hy, params, incision=IP, filled=filled, crown_mask=hidden)
    assert np.array_equal(got.crowns, ref.crowns) and np.array_equal(got.network.cells, ref.network.cells)
    assert np.array_equal(got.gully, ref.gully) and np.array_equal(got.bridged, ref.bridged) and ref.bridged.any()
    # given the surface the fill was made from (the rule's path), the map does not make it again: same map
    given = map_gullies(z, grid, hx, hy, params, incision=IP, filled=filled, crown_mask=hidden, trace_surface=z_trace)
    assert given.n_raised == ref.n_raised and np.array_equal(given.gully, ref.gully)
    assert np.array_equal(given.bridged, ref.bridged) and np.array_equal(given.network.cells, ref.network.cells)
    # a fill made on another surface than the crowns' cannot be checked: without the mask it is refused
    with pytest.raises(ValueError, match="needs the crown mask"):
        map_gullies(z, grid, hx, hy, params, incision=IP, ortho=rgb, filled=filled)
    with pytest.raises(ValueError, match="crown mask has shape"):
        map_gullies(z, grid, hx, hy, params, incision=IP, filled=filled, crown_mask=hidden[1:])

def test_hidden_reaches_on_a_chain():
    # a straight chain of 10 cells along a row: pos_down i -> i + 1
    shape = (3, 12)
    cells = np.arange(12, 22, dtype=np.int64)  # row 1, columns 0..9
    pos_down = np.append(np.arange(1, 10), -1).astype(np.int64)
    keep = np.zeros(shape, dtype=bool)
    hidden = np.zeros(shape, dtype=bool)
    keep[1, [0, 1, 7, 8, 9]] = True
    hidden[1, 2:7] = True
    b = hidden_reaches(cells, pos_down, keep, hidden, 1.0, None)
    assert b[1].tolist() == [False, False, True, True, True, True, True] + [False] * 5
    assert not hidden_reaches(cells, pos_down, keep, hidden, 1.0, 5.0).any()  # the gap is 6 m, end to end
    assert hidden_reaches(cells, pos_down, keep, hidden, 1.0, 6.0).sum() == 5
    hidden[1, 4] = False  # one cell of the gap in the open: the DSM there shows no incision, not a hidden reach
    assert not hidden_reaches(cells, pos_down, keep, hidden, 1.0, None).any()
    hidden[1, 4] = True
    keep[1, 7:] = False  # nothing mapped downstream
    assert not hidden_reaches(cells, pos_down, keep, hidden, 1.0, None).any()


def test_crown_mask_parts():
    # harmonic interpolation keeps a plane exactly
    yy, xx = np.mgrid[0:30, 0:40].astype(np.float64)
    plane = 0.1 * xx - 0.05 * yy
    m = np.zeros(plane.shape, dtype=bool)
    m[10:20, 5:30] = True
    out, n = interpolate_under(np.where(m, 9.0, plane), m)
    assert n == m.sum()
    assert np.allclose(out, plane, atol=1e-9)
    m[10:20, 30:] = True  # touching the grid edge: a no-flux edge there, values stay within the rim's
    out, n = interpolate_under(np.where(m, 9.0, plane), m)
    assert n == m.sum() and out[m].max() <= plane[~m].max() + 1e-9 and out[m].min() >= plane[~m].min() - 1e-9
    # a scene without foliage has no two-peak ExG histogram: no threshold, no crowns
    rng = np.random.default_rng(1)
    rgb = SOIL[:, None, None] + rng.normal(0.0, 3.0, (3, 50, 50))
    exg = excess_green(rgb)
    assert abs(np.nanmedian(exg)) < 0.05
    p = CrownParams(enabled=True)
    assert green_threshold(exg, p) is None
    z = np.zeros((50, 50), dtype=np.float32)
    mask, info = crown_mask(z + 1.0, exg, z, 0.2, CELL, p)
    assert not mask.any() and info["green_threshold"] is None
    with pytest.raises(InputError, match="gully.crowns has unknown key"):
        CrownParams.from_config({"enabled": True, "exg_k": 3})
    with pytest.raises(InputError, match="bridge_max_m >= 0"):
        CrownParams.from_config({"enabled": True, "bridge_max_m": -1})
    assert GullyParams.from_config({**_base_cfg(), "crowns": {"enabled": True, "window_m": 1.0}}).crowns.enabled
    assert not GullyParams.from_config(_base_cfg()).crowns.enabled
    with pytest.raises(ValueError, match="needs the orthophoto"):
        map_gullies(z, _grid_small(), np.zeros(0), np.zeros(0), _params(True), incision=IP)


def _base_cfg():
    return {k: getattr(GullyParams(), k) for k in GullyParams.__dataclass_fields__ if k not in ("trace_ground", "crowns")}


def _grid_small():
    return GridSpec(x0=0.0, y0=50 * CELL, cell=CELL, width=50, height=50, crs="EPSG:32632")


def test_interpolation_in_batches_of_whole_crowns_equals_one_solve():
    """Crowns solved a few at a time (a full-size site's 15 M cells) give the one-solve surface."""
    from kitegully.gully.crowns import interpolate_under

    rng = np.random.default_rng(3)
    z = rng.normal(0.0, 1.0, (60, 80)).cumsum(axis=1)
    mask = rng.random((60, 80)) < 0.35  # many small groups, some merged into larger ones
    z[5, 5] = np.nan
    whole, n_whole = interpolate_under(z, mask, max_unknowns=10**9)
    batched, n_batched = interpolate_under(z, mask, max_unknowns=7)
    assert n_whole == n_batched > 0
    np.testing.assert_allclose(batched, whole, rtol=0, atol=1e-9, equal_nan=True)
    assert not np.allclose(whole[mask & np.isfinite(z)], z[mask & np.isfinite(z)])


def test_foliage_threshold_when_grass_and_shrubs_merge_in_the_two_peak_smoothing():
    # soil (74 %), grass (ExG 0.13) and shrubs (0.25), like held-out h26: the two-peak smoothing merges grass and
    # shrubs and fills the valley above the soil; the threshold is that valley, not "no crowns" (session 43)
    rng = np.random.default_rng(2)
    n = 400_000
    exg = np.concatenate([rng.normal(0.0, 0.006, int(0.74 * n)), rng.normal(0.13, 0.008, int(0.17 * n)),
                          rng.normal(0.248, 0.015, int(0.07 * n)), rng.uniform(0.0, 0.25, int(0.02 * n))])
    thr = green_threshold(exg, CrownParams(enabled=True))
    assert thr is not None and 0.03 < thr < 0.11
