"""Flat resolution (Barnes et al. 2014) and open-water holes: every cell drains, paths converge, paths end at outlets."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.ndimage as ndi

from kitegully.gully.params import GullyParams
from kitegully.terrain import interpolate_holes, priority_flood_fill, trace_paths
from kitegully.terrain.flats import flow_directions
from kitegully.terrain.flow import D8_OFFSETS, END_MERGE, END_OUTLET, END_PIT
from kitegully.terrain.holes import interior_holes_below


def outlet_mask(valid: np.ndarray) -> np.ndarray:
    pv = np.pad(valid, 1, constant_values=False)
    h, w = valid.shape
    m = np.zeros_like(valid)
    for dr, dc in D8_OFFSETS:
        m |= ~pv[1 + dr : 1 + dr + h, 1 + dc : 1 + dc + w]
    return m & valid


def terminal_cells(dirs: np.ndarray) -> np.ndarray:
    """Cell where the flow from each cell ends (pointer doubling; a cycle would never reach a fixed point)."""
    h, w = dirs.shape
    idx = np.arange(h * w)
    d = dirs.ravel()
    has = d != 255
    nxt = idx.copy()
    nxt[has] = idx[has] + D8_OFFSETS[d[has], 0] * w + D8_OFFSETS[d[has], 1]
    for _ in range(int(np.ceil(np.log2(h * w))) + 1):
        nxt = nxt[nxt]
    assert np.array_equal(nxt[nxt], nxt), "flow directions contain a cycle"
    return nxt.reshape(h, w)


def flat_strip(rows: int = 21, cols: int = 60) -> np.ndarray:
    """A flat valley floor (10 m) between walls (20 m), closed upstream, open to the right grid edge."""
    z = np.full((rows + 4, cols), 20.0)
    z[2 : 2 + rows, 1:] = 10.0
    return z


def test_flat_strip_every_cell_drains_and_paths_converge():
    z = flat_strip()
    filled, n_raised = priority_flood_fill(z, 0.0)
    assert n_raised == 0  # not a depression: the flat is left exactly flat
    dirs, n_resolved, n_left = flow_directions(filled)
    valid = np.isfinite(filled)
    inner = valid & ~outlet_mask(valid)
    assert n_left == 0
    assert np.all(dirs[inner] != 255)
    assert n_resolved == int(np.count_nonzero(inner & (filled == 10.0)))
    # every cell's flow ends at an outlet (no cycle, no undrained cell)
    term = terminal_cells(dirs).ravel()
    assert np.all(outlet_mask(valid).ravel()[term[inner.ravel()]])
    # heads in the two upstream corners of the floor: with flat resolution they are pushed
    # away from the walls and meet in the middle of the floor long before the outlet column
    w = z.shape[1]
    heads = np.array([2 * w + 1, 22 * w + 1])
    cells, _down, starts, ends = trace_paths(filled, heads, dirs)
    assert ends.tolist() == [END_OUTLET, END_MERGE]
    meet = cells[starts[2] - 1]  # the merge cell of the second path: last cell it reached
    meet_row, meet_col = divmod(int(meet), w)
    assert meet_col < w // 2, f"paths only met at column {meet_col} of {w}"
    # the second path never climbs: it stays on the floor
    assert np.all(filled.ravel()[cells[starts[1] : starts[2]]] == 10.0)
    # the ε-fill routes the same floor on parallel rows: the two paths never meet
    eps_filled, _ = priority_flood_fill(z, 1e-4)
    _c, _d, _s, eps_ends = trace_paths(eps_filled, heads)
    assert eps_ends.tolist() == [END_OUTLET, END_OUTLET]


def test_filled_lake_paths_converge_to_the_spill_point():
    """A closed basin with a flat lake after filling (ε = 0): paths from every shore cell meet inside it."""
    n = 41
    yy, xx = np.mgrid[0:n, 0:n].astype(float)
    z = 5.0 + 0.05 * np.hypot(yy - 20, xx - 20)  # bowl
    z[20, 35:] = 5.5  # spillway to the right edge
    filled, n_raised = priority_flood_fill(z, 0.0)
    assert n_raised > 0
    dirs, n_resolved, n_left = flow_directions(filled)
    valid = np.isfinite(filled)
    inner = valid & ~outlet_mask(valid)
    assert n_left == 0 and n_resolved > 0
    assert np.all(dirs[inner] != 255)
    term = terminal_cells(dirs)
    assert np.all(outlet_mask(valid)[np.unravel_index(term[inner], z.shape)])
    lake = filled > z
    heads = np.flatnonzero((lake & ~ndi.binary_erosion(lake)).ravel())  # the lake shore
    cells, _d, starts, ends = trace_paths(filled, heads, dirs)
    assert np.count_nonzero(ends == END_OUTLET) == 1  # one path reaches the outlet, all others merge into it
    assert np.all(ends != END_PIT)
    # converging: the network holds far fewer cells than the shore cells' independent
    # straight paths to the spillway would (each at least its chessboard distance)
    rr, cc = np.divmod(heads, n)
    independent = np.maximum(np.abs(rr - 20), np.abs(cc - 35)).sum()
    assert cells.size < 0.5 * independent


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_random_dems_every_cell_drains_downhill_to_an_outlet(seed):
    rng = np.random.default_rng(seed)
    z = np.round(rng.normal(size=(48, 52)) * 2.0) / 2.0  # coarse steps: many flats and pits
    z[rng.random(z.shape) < 0.04] = np.nan
    filled, _ = priority_flood_fill(z, 0.0)
    dirs, _n_resolved, n_left = flow_directions(filled)
    valid = np.isfinite(filled)
    inner = valid & ~outlet_mask(valid)
    assert n_left == 0
    assert np.all(dirs[inner] != 255)
    assert np.all(dirs[~inner] == 255)
    # every step goes to a valid neighbour that is not higher (strictly lower or the same flat)
    r, c = np.nonzero(inner)
    d = dirs[r, c]
    rn, cn = r + D8_OFFSETS[d, 0], c + D8_OFFSETS[d, 1]
    assert np.all(valid[rn, cn])
    assert np.all(filled[rn, cn] <= filled[r, c])
    term = terminal_cells(dirs)
    assert np.all(outlet_mask(valid)[np.unravel_index(term[inner], z.shape)])
    heads = rng.choice(np.flatnonzero(valid.ravel()), 30, replace=False)
    _c, _d, _s, ends = trace_paths(filled, heads, dirs)
    assert np.all(ends != END_PIT)


def test_closed_flat_without_outlet_is_left_undrained_and_ends_in_a_pit():
    """Unfilled closed flat: nothing to resolve towards; the path ends in a documented pit."""
    z = np.full((12, 12), 9.0)
    z[3:9, 3:9] = 4.0
    dirs, _n_resolved, n_left = flow_directions(z)
    assert n_left == 36
    assert np.all(dirs[3:9, 3:9] == 255)
    _c, _d, _s, ends = trace_paths(z, np.array([5 * 12 + 5]), dirs)
    assert ends.tolist() == [END_PIT]


def test_open_water_hole_kept_and_network_ends_at_its_shore():
    """A large interior hole (a lake the matcher could not see) stays nodata; the path ends at its shore."""
    n = 60
    yy, xx = np.mgrid[0:n, 0:n].astype(float)
    z = 10.0 + 0.1 * np.abs(xx - 30) + 0.02 * yy  # valley draining north (row 0)
    lake = (np.abs(yy - 30) < 8) & (np.abs(xx - 30) < 8)
    small = (yy - 50) ** 2 + (xx - 10) ** 2 <= 2
    z[lake | small] = np.nan
    assert interior_holes_below(np.isfinite(z), 100).sum() == small.sum()
    zi, n_interp = interpolate_holes(z, max_cells=100)
    assert n_interp == small.sum()
    assert np.all(np.isnan(zi[lake])) and np.all(np.isfinite(zi[small]))
    filled, _ = priority_flood_fill(zi, 0.0)
    dirs, _nr, n_left = flow_directions(filled)
    assert n_left == 0
    head = 55 * n + 30  # on the valley axis below (south of) the lake
    cells, _d, _s, ends = trace_paths(filled, np.array([head]), dirs)
    assert ends.tolist() == [END_OUTLET]
    last_r, last_c = divmod(int(cells[-1]), n)
    assert 37 <= last_r <= 38 and abs(last_c - 30) <= 8  # the lake's south shore, not the grid edge
    # every interior hole interpolated: the same path runs on across the lake to the grid edge
    zi_all, n_all = interpolate_holes(z)
    assert n_all == lake.sum() + small.sum()
    filled_all, _ = priority_flood_fill(zi_all, 0.0)
    dirs_all, _nr, _nl = flow_directions(filled_all)
    cells_all, _d, _s, _e = trace_paths(filled_all, np.array([head]), dirs_all)
    assert divmod(int(cells_all[-1]), n)[0] == 0


def test_flat_routing_key_checked():
    with pytest.raises(ValueError, match="flat_routing"):
        GullyParams(flat_routing="d-infinity")


# ----------------------------------------------------------------------- phases of flat resolution
def test_neighbour_step_and_bounds():
    from kitegully.terrain.flats import _inner_neighbour, _neighbour

    h, w = 5, 6
    got = [_neighbour(0, 0, k, h, w, D8_OFFSETS) for k in range(8)]
    # only E (0, 1), S (1, 0) and SE (1, 1) of the top-left corner are inside
    assert got == [-1, -1, -1, -1, 1, -1, 6, 7]
    assert [_neighbour(2, 3, k, h, w, D8_OFFSETS) for k in range(8)] == [8, 9, 10, 14, 16, 20, 21, 22]
    # cells known to be inside: the same step without the bounds test
    assert [_inner_neighbour(2, 3, k, w, D8_OFFSETS) for k in range(8)] == [8, 9, 10, 14, 16, 20, 21, 22]


def test_flat_phases_on_a_plateau_walled_on_the_west():
    """5 x 6 flat at 1 m with a 2 m wall in column 0: 12 interior cells have no lower
    neighbour; the edge cells drain (outlets) and are the low edge; the interior cells
    next to the wall are the high edge; one flat; every interior cell is resolved."""
    from kitegully.terrain.flats import _d8_pass, _drain_flats, _flat_edges, _flat_mask, _label_flats
    from kitegully.terrain.flow import _INV_DIST

    z = np.ones((5, 6))
    z[:, 0] = 2.0
    h, w = z.shape
    flat = z.ravel()
    dirs, outlet, n_noflow = _d8_pass(flat, h, w, D8_OFFSETS, _INV_DIST)
    assert n_noflow == 12 and outlet.sum() == 18 and (dirs == 255).all()
    low, nlow, high, nhigh = _flat_edges(flat, h, w, D8_OFFSETS, dirs, outlet)
    assert sorted(high[:nhigh].tolist()) == [1 * w + 1, 2 * w + 1, 3 * w + 1]
    low = low[:nlow]
    assert outlet[low].all() and (flat[low] == 1.0).all() and 0 * w + 2 in low.tolist()
    labels, nlab, queue = _label_flats(flat, h, w, D8_OFFSETS, low, nlow)
    assert nlab == 1 and (labels.reshape(h, w)[:, 1:] == 1).all() and (labels.reshape(h, w)[:, 0] == 0).all()
    mask = _flat_mask(queue, labels, nlab, dirs, outlet, low, nlow, high, nhigh, h, w, D8_OFFSETS).reshape(h, w)
    inner = mask[1:4, 1:5]
    # low-edge cells are the towards-BFS seeds (level 1 -> 2); the wall is off the flat
    assert (inner > 0).all() and (mask[0, 1:] == 2).all() and (mask[:, 0] == 0).all()
    # nearer the wall (away gradient) and farther from the outlets (towards gradient): higher mask
    assert inner[1, 0] > inner[1, 1]
    n_resolved, n_left = _drain_flats(flat, h, w, D8_OFFSETS, _INV_DIST, dirs, outlet, labels, mask.ravel())
    assert (n_resolved, n_left) == (12, 0)
    d = dirs.reshape(h, w)
    assert (d[1:4, 1:5] != 255).all()
    # nothing flows west into the wall
    west = {0, 3, 5}  # NW, W, SW
    assert not any(int(k) in west for k in d[1:4, 1])
    full, nr, nl = flow_directions(z)
    assert np.array_equal(full, d) and (nr, nl) == (12, 0)
