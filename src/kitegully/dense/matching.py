"""Object-space multi-view matching of one tile, coarse to fine (after MicMac's Malt).

For each ground cell the matcher searches the elevation that maximises the multi-image
normalised cross-correlation of small ground windows resampled from every image that sees
the cell. The search runs over an image pyramid: at the coarsest level every elevation
between the tile's bounds is tried; each finer level searches a few steps around the
upsampled surface of the level above, and optional extra passes at the finest level search
around the finest surface itself. Costs are aggregated semi-globally (SGM) along 4 or
8 directions, the winner is refined to sub-step precision with a parabola, and cells seen
by fewer than two usable images or with a low correlation are masked.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, fields
from typing import Any, ClassVar, Mapping

import cv2
import numpy as np
from scipy import ndimage

from kitegully import InputError
from numba.typed import List

from kitegully.dense.kernels import (multiview_ncc_stack, ncc_cost, sample_stack, sgm_aggregate,
                                     sgm_winner)
from kitegully.dense.view_selection import select_views
from kitegully.dense.views import PyramidCache, ViewSet
from kitegully.io.raster import GridSpec
from kitegully.terrain.holes import fill_nearest

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class MatchParams:
    """Parameters of the matcher (the ``dense.matching`` config section).

    Attributes
    ----------
    levels : int
        Pyramid levels of the ground grid (cell × 2**l, l = levels−1 … 0).
    window_half_cells : int
        Correlation window half-size (cells); the window is (2h+1)².
    z_step_cells : float
        Elevation step of the search at each level as a parallax, in cells of that level:
        ``dz = z_step_cells · cell · H/B`` with H/B the tile's height-to-base ratio
        (median over image pairs), so that one step shifts the image windows by about
        ``z_step_cells`` cells whatever the geometry (MicMac's ZPas).
    refine_radius_steps : int
        Steps searched either side of the upsampled surface at finer levels.
    max_labels : int
        Upper bound on elevation labels at the coarsest level (the step grows if needed).
    z_margin_m : float
        Margin added to the tie-point elevation range of a tile (m).
    p1, p2 : float
        SGM penalties (cost units, cost = (1 − NCC)/2) for a one-step change and a jump.
    sgm_directions : int
        4 or 8 aggregation directions.
    min_correlation : float
        Cells whose NCC at the chosen elevation is lower are masked.
    min_views : int
        Cells need at least this many usable images (≥ 2).
    min_std_dn : float
        Windows with a grey-level SD below this (DN, 0–255) are textureless and unused: set
        it above the camera's noise SD, where a window's NCC measures noise, not the ground
        (water, the twin's reservoir). Given for full-resolution images; for a view sampled
        at pyramid level ``s`` (2×2 means) the threshold is ``min_std_dn / 2**s``, as the
        noise SD halves with each level while the ground's coarser texture largely survives.
    nan_cost : float
        Cost of a candidate no two images can judge.
    final_passes : int
        Passes at the finest level. Pass 1 searches around the surface of the coarser
        level, whose cells (and windows) are wider than tree crowns and gully walls, so
        next to them that prior is off by up to the objects' height and the narrow
        refine window misses the ground. Each further pass searches again around the
        level-0 surface of the previous pass (masked cells take the nearest valid cell's
        elevation); the masking rules are the same in every pass.
    final_window_half_cells : int or None
        Correlation window half-size of the last pass at the finest level (``None`` = the
        same as ``window_half_cells``). Used only with ``final_passes`` ≥ 2, where that pass
        searches a few steps around a surface the wider window has already fixed. That pass
        is matched with both windows; the narrow window's cell is taken where its NCC reaches
        :func:`equal_significance_correlation` (``min_correlation`` scaled so that a window
        of pure noise passes as rarely as it does the wider window's test), else the site
        window's cell of the same pass (11 % more time on the default twin's head boxes).
    max_views : int or None
        At most this many images match a tile (block plus halo), chosen from those whose
        frame meets it by :func:`kitegully.dense.view_selection.select_views` (coverage
        of the tile, resolution at the DSM cell, angular diversity; geometry only).
        ``None`` (default) uses every image. The cost of a tile is O(V) per cell and
        label, while the noise of the mean pairwise NCC falls only as 1/sqrt(V) and
        near-duplicate viewpoints add no parallax. Tiles seen by at most this many images
        are matched exactly as without a cap. [I] Keep it at most ``dense.max_cached_images``:
        every pass reads a tile's images in the same order, so an LRU cache smaller than
        that set misses on every read and each pass re-reads all of them.
    """

    levels: int = 4
    window_half_cells: int = 2
    z_step_cells: float = 0.5
    refine_radius_steps: int = 3
    max_labels: int = 96
    z_margin_m: float = 2.0
    p1: float = 0.02
    p2: float = 0.12
    sgm_directions: int = 8
    min_correlation: float = 0.5
    min_views: int = 2
    min_std_dn: float = 1.0
    nan_cost: float = 1.0
    final_passes: int = 1
    max_views: int | None = None
    final_window_half_cells: int | None = None

    OPTIONAL: ClassVar[tuple[str, ...]] = ("max_views", "final_window_half_cells")  # keys a config section may leave out
    REQUIRED: ClassVar[tuple[str, ...]] = ()  # set below: every other field

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any]) -> "MatchParams":
        """Build from ``dense.matching`` (keys of the same names; others ignored); raises InputError on a bad value."""
        p = cls(**{f.name: cfg[f.name] for f in fields(cls) if f.name in cfg})
        if p.sgm_directions not in (4, 8):
            raise InputError(f"dense.matching.sgm_directions: must be 4 or 8, got {p.sgm_directions}")
        if p.min_views < 2:
            raise InputError("dense.matching.min_views: must be at least 2")
        if p.final_passes < 1:
            raise InputError("dense.matching.final_passes: must be at least 1")
        if p.final_window_half_cells is not None and (isinstance(p.final_window_half_cells, bool)
                                                      or not isinstance(p.final_window_half_cells, (int, np.integer))
                                                      or p.final_window_half_cells < 1):
            raise InputError("dense.matching.final_window_half_cells: must be null or an integer >= 1 (a 3 x 3 "
                             f"window or wider), got {p.final_window_half_cells!r}")
        if p.max_views is not None and (isinstance(p.max_views, bool) or not isinstance(p.max_views, (int, np.integer))
                                        or p.max_views < p.min_views):
            raise InputError(f"dense.matching.max_views: must be null or an integer >= min_views ({p.min_views}), "
                             f"got {p.max_views!r}")
        return p


MatchParams.REQUIRED = tuple(f.name for f in fields(MatchParams) if f.name not in MatchParams.OPTIONAL)


@dataclass
class TileResult:
    """Surface of one tile at level 0: elevation (local), NCC and usable image count; and the
    number of images the tile was matched with (after the ``max_views`` cap)."""

    z: np.ndarray
    ncc: np.ndarray
    nviews: np.ndarray
    images: int = 0


def view_levels(views: ViewSet, idx: list[int], z_ground: float, cell: float) -> np.ndarray:
    """Image pyramid level per view whose pixel size is closest to ``cell`` (in log scale), so
    the 2×2-mean pyramid acts as the anti-aliasing filter of the ground resampling.

    Parameters
    ----------
    views : ViewSet
        The oriented images.
    idx : list of int
        Indices of the views in ``views.images``.
    z_ground : float
        Ground elevation (local, m) at which each view's nadir pixel size is taken.
    cell : float
        Ground cell size (m).

    Returns
    -------
    ndarray (len(idx),) int
        Pyramid level of each view (0 or more).
    """
    gsd = np.array([views.images[i].gsd_at(z_ground) for i in idx])
    ratio = np.maximum(cell / np.maximum(gsd, 1e-9), 1.0)
    return np.floor(np.log2(ratio) + 0.5).astype(int)


def visible_views(views: ViewSet, x: tuple[float, float], y: tuple[float, float], z: tuple[float, float]) -> list[int]:
    """Images whose frame intersects the box ``x × y × z`` (local coordinates).

    Parameters
    ----------
    views : ViewSet
        The oriented images.
    x, y, z : (float, float)
        Low and high bounds of the box along each axis (local, m).

    Returns
    -------
    list of int
        Indices in ``views.images`` of the images that have all eight corners of the box in front of the camera
        and the bounding box of their projections overlapping the frame.
    """
    X = np.array([[a, b, c] for a in x for b in y for c in z], float)
    out = []
    for k, v in enumerate(views.images):
        u, w, d = v.project(X)
        if np.any(d <= 0):
            continue
        if u.max() < 0 or w.max() < 0 or u.min() > v.width - 1 or w.min() > v.height - 1:
            continue
        out.append(k)
    return out


def height_base_ratio(views: ViewSet, idx: list[int], z_ground: float, max_ratio: float = 20.0) -> float:
    """Median over image pairs of flying height / horizontal base, clipped to [1, ``max_ratio``].

    Parameters
    ----------
    views : ViewSet
        The oriented images.
    idx : list of int
        Indices of the images in ``views.images``.
    z_ground : float
        Ground elevation (local, m); the flying height is the median camera height above it.
    max_ratio : float
        Upper bound of the ratio, also returned when fewer than two images are given.

    Returns
    -------
    float
        The height-to-base ratio.
    """
    C = np.array([views.images[i].C for i in idx])
    if len(C) < 2:
        return max_ratio
    iu = np.triu_indices(len(C), 1)
    base = np.hypot(*(C[:, None, :2] - C[None, :, :2]).transpose(2, 0, 1))[iu]
    height = np.median(C[:, 2]) - z_ground
    b = np.median(base)
    return float(np.clip(height / max(b, 1e-9), 1.0, max_ratio))


def _label_range(params: MatchParams, z_prev: np.ndarray | None, zlo: float, zhi: float, dz: float,
                 hl: int, wl: int) -> tuple[np.ndarray, int, float]:
    """Elevation labels of one pass: lowest label per cell, label count K and step dz.

    The first (coarsest) pass spans the tile's elevation bounds with at most
    ``max_labels`` labels (dz widened if needed); later passes search ±``refine_radius_steps``
    around the previous surface, upsampled, kept inside the bounds."""
    if z_prev is None:
        K = int(np.ceil((zhi - zlo) / dz)) + 1
        if K > params.max_labels:
            K = params.max_labels
            dz = (zhi - zlo) / (K - 1)
        base = np.full((hl, wl), zlo, np.float64)
    else:
        up = cv2.resize(z_prev.astype(np.float32), (wl, hl), interpolation=cv2.INTER_LINEAR).astype(np.float64)
        K = 2 * params.refine_radius_steps + 1
        # the search window stays inside the tile's elevation bounds
        base = np.clip(up - params.refine_radius_steps * dz, zlo, max(zlo, zhi - (K - 1) * dz))
    return base, K, dz


def _ncc_volume(views: ViewSet, cache: PyramidCache, idx: list[int], cams: tuple, levels: np.ndarray,
                xl: np.ndarray, yl: np.ndarray, base: np.ndarray, dz: float, K: int,
                params: MatchParams, half: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Multi-view NCC (K, h, w) and usable image count per label, from the images
    resampled at each label's elevation (``cams`` = stacked R, C and intrinsics)."""
    Rs, Cs, Ps = cams
    hl, wl = len(yl), len(xl)
    imgs = List()
    for i, s in zip(idx, levels):
        imgs.append(cache.level(i, int(s)))
    stack = np.empty((K, len(idx), hl, wl), np.float32)
    sample_stack(imgs, Rs, Cs, Ps, levels.astype(np.int64), xl, yl, base, float(dz), stack)
    score = np.empty((K, hl, wl), np.float32)
    nvw = np.empty((K, hl, wl), np.int16)
    # the texture test is against the image noise, which the 2x2-mean pyramid halves per level
    min_std = params.min_std_dn / 2.0 ** levels.astype(np.float64)
    multiview_ncc_stack(stack, params.window_half_cells if half is None else half, min_std, score, nvw)
    return score, nvw


def _sgm_winner(score: np.ndarray, K: int, params: MatchParams) -> tuple[np.ndarray, np.ndarray]:
    """Winning label per cell after semi-global aggregation of ``(1 − NCC)/2`` and its
    sub-step offset in [−0.5, 0.5] (parabola through the aggregated costs around it).

    The cost is transposed to (H, W, K) by one compiled pass and the winner and parabola
    are fused in one compiled pass (no numpy temporaries); equal bit for bit to
    :func:`_sgm_winner_reference`.
    """
    k, h, w = score.shape
    cost = np.empty((h, w, k), np.float32)
    ncc_cost(score, float(params.nan_cost), cost)
    agg = sgm_aggregate(cost, params.p1, params.p2, params.sgm_directions)
    d = np.empty((h, w), np.int64)
    off = np.empty((h, w), np.float32)
    sgm_winner(agg, d, off)
    return d, off


def _sgm_winner_reference(score: np.ndarray, K: int, params: MatchParams) -> tuple[np.ndarray, np.ndarray]:
    """The former numpy implementation of :func:`_sgm_winner` (tests, benchmark)."""
    cost = np.where(np.isfinite(score), (1.0 - score) * 0.5, params.nan_cost).astype(np.float32)
    agg = sgm_aggregate(np.moveaxis(cost, 0, -1), params.p1, params.p2, params.sgm_directions)
    d = np.argmin(agg, axis=2)
    dc = np.clip(d, 1, K - 2) if K >= 3 else d
    r, c = np.indices(d.shape)
    if K >= 3:
        cm, c0, cp = agg[r, c, dc - 1], agg[r, c, dc], agg[r, c, dc + 1]
        den = cm - 2 * c0 + cp
        with np.errstate(divide="ignore", invalid="ignore"):
            off = np.where((den > 1e-12) & (d == dc), 0.5 * (cm - cp) / den, 0.0)
        off = np.clip(off, -0.5, 0.5)
    else:
        off = np.zeros(d.shape)
    return d, off


def equal_significance_correlation(min_correlation: float, half_wide: int, half_narrow: int) -> float:
    """The NCC threshold of a narrower window as significant as ``min_correlation`` of a wider one.

    The NCC of two windows of n independent noise samples has a standard deviation of about
    1/sqrt(n − 1), so a threshold t on the wide window (n_w samples) lies t·sqrt(n_w − 1)
    noise SDs above zero; the narrow window (n_n samples) needs t·sqrt((n_w − 1)/(n_n − 1))
    to stand as many SDs above it (averaging over views scales both alike).

    Parameters
    ----------
    min_correlation
        Threshold of the wide window.
    half_wide, half_narrow
        Window half-sizes (cells): windows of (2·half + 1)² samples.

    Returns
    -------
    float
        The narrow window's threshold (above 1 when no narrow window can pass it).
    """
    n_wide, n_narrow = (2 * half_wide + 1) ** 2, (2 * half_narrow + 1) ** 2
    return float(min_correlation * np.sqrt((n_wide - 1) / (n_narrow - 1)))


def _match_pass(views: ViewSet, cache: PyramidCache, idx, cams: tuple, levels_v, xl: np.ndarray, yl: np.ndarray,
                base: np.ndarray, dz: float, K: int, params: MatchParams, half: int) -> tuple[np.ndarray, ...]:
    """One pass with a (2·half + 1)² window: winning label ``d``, elevation, its NCC and view count,
    and the cells seen by ``min_views`` images at any label."""
    score, nvw = _ncc_volume(views, cache, idx, cams, levels_v, xl, yl, base, dz, K, params, half)
    d, off = _sgm_winner(score, K, params)
    r, c = np.indices(d.shape)
    return d, base + (d + off) * dz, score[d, r, c], nvw[d, r, c], nvw.max(axis=0) >= params.min_views


def _kept(ok: np.ndarray, d: np.ndarray, base: np.ndarray, dz: float, K: int, zlo: float, zhi: float) -> np.ndarray:
    """``ok`` without the winners on the tile's lowest or highest searchable elevation: they have no
    cost minimum inside the bounds, so the surface is not there (or not seen)."""
    at_bound = ((d == 0) & (base <= zlo + 1e-6)) | ((d == K - 1) & (base + (K - 1) * dz >= zhi - 1e-6))
    return ok & ~at_bound


def match_tile(views: ViewSet, cache: PyramidCache, xs: np.ndarray, ys: np.ndarray, cell: float,
               z_range: tuple[float, float], params: MatchParams) -> TileResult:
    """Match one tile coarse to fine.

    Parameters
    ----------
    xs, ys
        Local coordinates of the level-0 cell centres (W,), (H,); W and H must be
        multiples of ``2**(levels − 1)``.
    z_range
        (low, high) local elevation bounds of the search.

    Cost: O(Σ_levels H_l·W_l·K_l·(V·w² + directions)) with K_l labels and V images
    (V ≤ ``params.max_views`` when set); with ``final_window_half_cells`` the last pass is matched
    with both windows.
    """
    H, W = len(ys), len(xs)
    L = params.levels
    f = 2 ** (L - 1)
    if H % f or W % f:
        raise ValueError(f"tile size {H}x{W} is not a multiple of {f}")
    zlo, zhi = float(z_range[0]), float(z_range[1])
    tile = GridSpec(xs[0] - cell / 2, ys[0] + cell / 2, cell, W, H, "")  # local frame, no CRS
    xmin, ymin, xmax, ymax = tile.bounds
    idx = visible_views(views, (xmin, xmax), (ymin, ymax), (zlo, zhi))
    nan = np.full((H, W), np.nan, np.float32)
    if len(idx) < params.min_views:
        return TileResult(nan, nan.copy(), np.zeros((H, W), np.int16))
    zmid = 0.5 * (zlo + zhi)
    # at most max_views images (all of them when the tile has no more): view_selection
    idx = select_views(views, idx, (xmin, ymin, xmax, ymax), zmid, cell, params.max_views)
    hb = height_base_ratio(views, idx, zmid)
    Rs = np.ascontiguousarray([views.images[i].R for i in idx], dtype=np.float64)
    Cs = np.ascontiguousarray([views.images[i].C for i in idx], dtype=np.float64)
    Ps = np.ascontiguousarray([views.images[i].params() for i in idx], dtype=np.float64)
    z_prev = None
    # coarse to fine, then ``final_passes − 1`` more passes at level 0 around the level-0 surface
    schedule = list(range(L - 1, -1, -1)) + [0] * (params.final_passes - 1)
    narrow_final = params.final_passes >= 2 and params.final_window_half_cells not in (None, params.window_half_cells)
    for n_pass, lev in enumerate(schedule):
        last = n_pass == len(schedule) - 1
        level_grid = tile.coarsened(2 ** lev)
        cl, hl, wl = level_grid.cell, level_grid.height, level_grid.width
        xl, yl = level_grid.cell_centres()
        dz = params.z_step_cells * cl * hb
        base, K, dz = _label_range(params, z_prev, zlo, zhi, dz, hl, wl)
        levels_v = view_levels(views, idx, zmid, cl)
        pass_args = (views, cache, idx, (Rs, Cs, Ps), levels_v, xl, yl, base, dz, K, params)
        d, z, ncc, nv, seen = _match_pass(*pass_args, params.window_half_cells)
        if not last:
            # keep only confident cells as the prior of the next level (or pass); the others take
            # the value of the nearest confident cell (ambiguous low-texture/low-base areas)
            good = seen & (nv >= params.min_views) & np.isfinite(ncc) & (ncc >= params.min_correlation)
            zf = np.where(good, z, np.nan)
            if not np.isfinite(zf).any():
                return TileResult(nan, nan.copy(), np.zeros((H, W), np.int16), len(idx))
            zf = fill_nearest(zf)
            z_prev = ndimage.median_filter(zf, size=3, mode="nearest")
        else:
            keep = _kept((nv >= params.min_views) & np.isfinite(ncc) & (ncc >= params.min_correlation),
                         d, base, dz, K, zlo, zhi)
            if narrow_final:
                # the narrow window's cell where it passes its own (higher) threshold; elsewhere the
                # site window's cell of this same pass stands (9 samples fail the texture and
                # correlation tests more often than 25)
                dn, zn, nccn, nvn, _ = _match_pass(*pass_args, params.final_window_half_cells)
                t = equal_significance_correlation(params.min_correlation, params.window_half_cells,
                                                   params.final_window_half_cells)
                narrow = _kept((nvn >= params.min_views) & np.isfinite(nccn) & (nccn >= t), dn, base, dz, K, zlo, zhi)
                z, ncc, nv = np.where(narrow, zn, z), np.where(narrow, nccn, ncc), np.where(narrow, nvn, nv)
                keep |= narrow
            z = np.where(keep, z, np.nan).astype(np.float32)
            log.debug("tile level %d: %d labels, %d views, %.0f%% kept", lev, K, len(idx), 100 * keep.mean())
            return TileResult(z, np.where(np.isfinite(ncc), ncc, np.nan).astype(np.float32), nv.astype(np.int16), len(idx))
    raise AssertionError("unreachable")
