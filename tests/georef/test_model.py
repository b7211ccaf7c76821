"""Tie-point choice for the GCP bundle: balanced over image cells vs longest tracks.

A strip of 8 nadir images, 60 m apart, footprints 200 m wide: a ground point is seen by
up to 4 images, points under the strip ends by 2 (points seen once are no tie points). With a budget of
a few hundred points the longest-track choice takes none from the outer half of the end
images (the kite block's strip-end cameras lost their ties in the same way); the balanced
choice gives every occupied cell of every image its best point first, which is guaranteed
when the budget is at least the number of occupied cells.
"""

from __future__ import annotations

import numpy as np

from kitegully.georef.model import select_tie_points

W, H = 2000, 1000  # px
FOOT = 200.0  # m along the strip, image width


def strip_observations(seed=1):
    rng = np.random.default_rng(seed)
    centres = np.arange(8) * 60.0
    X = rng.uniform(centres[0] - FOOT / 2, centres[-1] + FOOT / 2, 6000)
    Y = rng.uniform(0, 1, len(X))
    oi, op, xy = [], [], []
    for i, c in enumerate(centres):
        u = (X - c) / FOOT + 0.5
        seen = (u >= 0) & (u < 1)
        oi.append(np.full(seen.sum(), i)), op.append(np.flatnonzero(seen))
        xy.append(np.column_stack([u[seen] * W, Y[seen] * H]))
    oi, op, xy = np.concatenate(oi), np.concatenate(op), np.concatenate(xy)
    tie = np.bincount(op, minlength=len(X))[op] >= 2
    oi, op, xy = oi[tie], op[tie], xy[tie]
    used = np.unique(op)
    remap = np.full(len(X), -1)
    remap[used] = np.arange(len(used))
    return oi, remap[op], xy, len(used), np.tile([W, H], (len(centres), 1)).astype(float)


def _cells_hit(oi, op, xy, keep, grid):
    nx, ny = grid
    sel = np.isin(op, keep)
    cell = (oi * ny + np.minimum((xy[:, 1] / H * ny).astype(int), ny - 1)) * nx + np.minimum((xy[:, 0] / W * nx).astype(int), nx - 1)
    return set(cell[sel]), set(cell)


def test_balanced_choice_covers_every_cell_of_every_image():
    oi, op, xy, n, size = strip_observations()
    grid = (4, 2)
    occupied = len(set(((oi * 2 + (xy[:, 1] / H * 2).astype(int)) * 4 + (xy[:, 0] / W * 4).astype(int)).tolist()))
    budget = occupied + 20
    keep = select_tie_points(oi, op, xy, n, budget, size, grid, np.random.default_rng(0))
    assert len(keep) == budget and len(np.unique(keep)) == budget
    hit, allc = _cells_hit(oi, op, xy, keep, grid)
    assert hit == allc


def test_longest_tracks_starve_the_strip_ends():
    oi, op, xy, n, size = strip_observations()
    keep = select_tie_points(oi, op, xy, n, 300, size, None, np.random.default_rng(0))
    track = np.bincount(op, minlength=n)
    assert np.all(track[keep] >= 3)
    # outer half of the first image: only points seen by 2 images lie there
    first_outer = np.isin(op, keep) & (oi == 0) & (xy[:, 0] < W / 2)
    assert first_outer.sum() == 0
    keep_b = select_tie_points(oi, op, xy, n, 300, size, (4, 2), np.random.default_rng(0))
    assert (np.isin(op, keep_b) & (oi == 0) & (xy[:, 0] < W / 2)).sum() >= 4  # its 2 × 2 outer cells


def test_zero_budget_keeps_all_points():
    oi, op, xy, n, size = strip_observations()
    assert len(select_tie_points(oi, op, xy, n, 0, size, (4, 2), np.random.default_rng(0))) == n
