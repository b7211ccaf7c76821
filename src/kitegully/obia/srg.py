"""Seeded region growing (Adams & Bischof 1994), compiled with numba.

Every valid cell joins exactly one region.  The boundary cells of all regions wait in
one binary min-heap keyed by their squared feature-space distance to the running mean
of the region that reached them (optionally plus a weighted squared distance to that
region's seed, SAGA's "feature space and position" [I]).  With ``reference="seed"`` the
distance is taken to the seed's own features instead of the running region mean, which
is what SAGA's ``imagery_segmentation`` tool 3 does (its seed table is never updated).  The cell with the smallest
key is labelled, its region mean is updated and its unlabelled 4-neighbours are pushed.
A cell can be pushed once per labelled neighbour, so the heap holds at most 4N entries
and the whole growth costs O(N log N).
"""

from __future__ import annotations

import numpy as np
from numba import njit
from scipy import ndimage


@njit(cache=True)
def _heap_push(keys, cells, labs, size, key, cell, lab):
    i = size
    keys[i] = key
    cells[i] = cell
    labs[i] = lab
    while i > 0:
        parent = (i - 1) >> 1
        if keys[parent] <= keys[i]:
            break
        keys[parent], keys[i] = keys[i], keys[parent]
        cells[parent], cells[i] = cells[i], cells[parent]
        labs[parent], labs[i] = labs[i], labs[parent]
        i = parent
    return size + 1


@njit(cache=True)
def _heap_pop(keys, cells, labs, size):
    cell = cells[0]
    lab = labs[0]
    size -= 1
    keys[0] = keys[size]
    cells[0] = cells[size]
    labs[0] = labs[size]
    i = 0
    while True:
        left = 2 * i + 1
        if left >= size:
            break
        child = left
        right = left + 1
        if right < size and keys[right] < keys[left]:
            child = right
        if keys[i] <= keys[child]:
            break
        keys[child], keys[i] = keys[i], keys[child]
        cells[child], cells[i] = cells[i], cells[child]
        labs[child], labs[i] = labs[i], labs[child]
        i = child
    return cell, lab, size


@njit(cache=True)
def _distance(feat, cell, lab, sums, counts, seed_feat, use_seed, seed_r, seed_c, ncols, pos_w):
    k = feat.shape[1]
    d = 0.0
    n = counts[lab]
    for j in range(k):
        ref = seed_feat[lab, j] if use_seed else sums[lab, j] / n
        diff = feat[cell, j] - ref
        d += diff * diff
    if pos_w > 0.0:
        dr = cell // ncols - seed_r[lab]
        dc = cell % ncols - seed_c[lab]
        d += pos_w * (dr * dr + dc * dc)
    return d


@njit(cache=True)
def _push_neighbours(cell, lab, labels, feat, sums, counts, seed_feat, use_seed, seed_r, seed_c,
                     nrows, ncols, pos_w, keys, cells, labs, size):
    """Queue the unlabelled 4-neighbours of ``cell`` for region ``lab``; returns the heap size."""
    r = cell // ncols
    c = cell % ncols
    for q in range(4):
        rr = r + (-1, 1, 0, 0)[q]
        cc = c + (0, 0, -1, 1)[q]
        if rr < 0 or rr >= nrows or cc < 0 or cc >= ncols:
            continue
        nb = rr * ncols + cc
        if labels[nb] == 0:
            key = _distance(feat, nb, lab, sums, counts, seed_feat, use_seed, seed_r, seed_c, ncols, pos_w)
            size = _heap_push(keys, cells, labs, size, key, nb, lab)
    return size


@njit(cache=True)
def _grow(feat, labels, nrows, ncols, nseeds, pos_w, use_seed):
    n = nrows * ncols
    k = feat.shape[1]
    sums = np.zeros((nseeds + 1, k), dtype=np.float64)
    counts = np.zeros(nseeds + 1, dtype=np.float64)
    seed_r = np.zeros(nseeds + 1, dtype=np.float64)
    seed_c = np.zeros(nseeds + 1, dtype=np.float64)
    for cell in range(n):
        lab = labels[cell]
        if lab > 0:
            for j in range(k):
                sums[lab, j] += feat[cell, j]
            counts[lab] += 1.0
            seed_r[lab] = cell // ncols
            seed_c[lab] = cell % ncols
    seed_feat = np.zeros((nseeds + 1, k), dtype=np.float64)
    for lab in range(1, nseeds + 1):
        if counts[lab] > 0:
            for j in range(k):
                seed_feat[lab, j] = sums[lab, j] / counts[lab]
    cap = 4 * n + 4
    keys = np.empty(cap, dtype=np.float64)
    cells = np.empty(cap, dtype=np.int64)
    labs = np.empty(cap, dtype=np.int32)
    size = 0
    for cell in range(n):
        lab = labels[cell]
        if lab > 0:
            size = _push_neighbours(cell, lab, labels, feat, sums, counts, seed_feat, use_seed, seed_r, seed_c,
                                    nrows, ncols, pos_w, keys, cells, labs, size)
    while size > 0:
        cell, lab, size = _heap_pop(keys, cells, labs, size)
        if labels[cell] != 0:
            continue
        labels[cell] = lab
        for j in range(k):
            sums[lab, j] += feat[cell, j]
        counts[lab] += 1.0
        size = _push_neighbours(cell, lab, labels, feat, sums, counts, seed_feat, use_seed, seed_r, seed_c,
                                nrows, ncols, pos_w, keys, cells, labs, size)
    return labels


def seeded_region_growing(
    features: np.ndarray,
    seeds: np.ndarray,
    valid: np.ndarray | None = None,
    position_weight: float = 0.0,
    reference: str = "mean",
) -> tuple[np.ndarray, int]:
    """Grow regions from seeds until every valid cell belongs to one.

    Parameters
    ----------
    features
        (rows, cols, k) feature stack (normalised).
    seeds
        int raster, 1..n at seed cells, 0 elsewhere.
    valid
        Cells that may be labelled; others get label 0 in the output.
    position_weight
        Weight of the squared distance (in cells) to the region's seed added to the
        squared feature distance; 0 = feature space only.
    reference
        ``"mean"``: distance to the running region mean (Adams & Bischof 1994);
        ``"seed"``: distance to the seed's features (SAGA's Seeded Region Growing).

    Returns
    -------
    (labels, n_segments)
        int32 labels 1..n_segments, 0 on invalid cells.  Valid areas that no seed
        reaches (cut off by invalid cells) become extra segments, one per connected
        piece.
    """
    rows, cols = seeds.shape
    if valid is None:
        valid = np.ones((rows, cols), dtype=bool)
    labels = np.where(valid, seeds, -1).astype(np.int32).ravel()
    nseeds = int(labels.max()) if labels.size else 0
    feat = np.ascontiguousarray(features.reshape(rows * cols, -1), dtype=np.float32)
    if reference not in ("mean", "seed"):
        raise ValueError(f"reference must be 'mean' or 'seed', got {reference!r}")
    labels = _grow(feat, labels, rows, cols, max(nseeds, 0), float(position_weight), reference == "seed")
    labels = labels.reshape(rows, cols)
    orphans = labels == 0
    n = nseeds
    if orphans.any():
        extra, m = ndimage.label(orphans)
        labels = np.where(orphans, extra + n, labels)
        n += m
    labels[labels < 0] = 0
    return labels.astype(np.int32), n
