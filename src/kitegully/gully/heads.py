"""Automatic gully-head detection from the DEM alone (scored by :mod:`kitegully.evaluate.heads`).

After the channel-head literature: a channel begins where concentrated flow has enough
contributing area A on a steep enough slope S to incise (Montgomery & Dietrich 1988,
1992: an area–slope threshold; Vandekerckhove et al. 2000 give ``S ≥ a·A^-b`` for gully
heads on Mediterranean cropland) and where the surface is concave across the flow
(Passalacqua et al. 2010 use curvature after smoothing; Clubb et al. 2014 the upstream end
of the concave, channelised reach). Here:

1. Concavity: a depth map at the scale of a gully head (``D_h = G_σh ∗ Z₀ − Z``, Z₀ the
   ground surface, the
   Gaussian depth of Fig. 3 a-d with a small σ, which is −σ²/2·∇²Z for smooth relief:
   a plan/profile curvature) deeper than ``k·max(σ_z, ρ)`` marks incised cells, with σ_z
   the DSM noise at the checkpoints and ρ the surface's own head-scale roughness (the
   robust spread of that depth map over the site, :func:`~kitegully.gully.relief.surface_roughness`: tillage
   furrows and crop rows of a photogrammetric DSM are not gullies). The smoothed surface is
   that of the DEM without raised objects (:func:`~kitegully.gully.relief.ground_surface`): on a DSM the ground at
   the foot of hedgerows and shrub rows otherwise looks incised at head scale. For the
   detector, tall objects (buildings, trees) are left out of that ground surface and of
   the Gaussian: the noise smoothing's skirt around them otherwise lifts the reference on a
   ring around each (:func:`~kitegully.gully.relief.head_scale_relief`).
2. Flow: D8 directions on the filled DEM, contributing area A (m²), slope S along the
   flow measured over the DSM's resolution.
3. Channel cells: incised cells with ``S ≥ a·A_ha^-b``.
   No channel cell within one matching window of a DSM gap (:func:`~kitegully.gully.relief.matched_cells`).
4. Heads: channel cells with no channel cell upstream whose path downstream stays in
   channel cells over most of ``min_channel_length_m`` (a channel, not a pit). Traced
   highest first; a candidate whose path joins one traced before within
   ``min_channel_length_m`` is a bank-side twin of that channel and is dropped, and so is
   one within the head-scale Gaussian's FWHM of a higher head (:func:`one_head_per_incision`).

Step 1's relief, ground surface and thresholds live in :mod:`kitegully.gully.relief`.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np
from numba import njit
from scipy.spatial import cKDTree

from kitegully import InputError
from kitegully.gully.relief import HeadScaleGround, dsm_noise_at_checkpoints, incision_map, matched_cells
from kitegully.io.raster import GridSpec
from kitegully.terrain.flow import D8_OFFSETS, END_MERGE, END_ON_NETWORK, trace_paths
from kitegully.terrain.smoothing import gaussian_smooth_fft

log = logging.getLogger(__name__)

#: Full width at half maximum of a Gaussian per σ, 2·sqrt(2 ln 2): [I] two incisions closer than the
#: FWHM of the head-scale Gaussian (4.7 m at σ_h 2 m) are one depression in its depth map.
FWHM_PER_SIGMA = 2.0 * np.sqrt(2.0 * np.log(2.0))

#: Values of ``gully.heads``.
HEAD_SOURCES = ("digitised", "automatic", "both")


@dataclass(frozen=True)
class HeadDetectionParams:
    """Parameters of :func:`detect_heads` (the ``gully.automatic_heads`` config section).

    Attributes
    ----------
    scale_m : float
        σ (m) of the head-scale depth map. [I] 2 m: twice the widest gully head of the
        site (≤ 1.5 m wide), so the depth of a head is resolved while field-scale
        relief (≥ 10 m) is smoothed away.
    relief_k : float
        Incised where the head-scale depth ≥ ``relief_k``·max(``dsm_sigma_z_m``, surface
        roughness) (:func:`~kitegully.gully.relief.surface_roughness`). [I] 3, as the operator's visibility rule
        (a 3σ step).
    dsm_sigma_z_m : float
        Vertical noise of the DSM (m). [I] ``null`` in the config = the SD of DSM minus
        the RTK checkpoints (:func:`~kitegully.gully.relief.dsm_noise_at_checkpoints`): the DSM's own noise where
        heads are (open ground), measured from observed data only.
    slope_window_m : float
        Slope S is measured on the DEM smoothed with this σ (m). [I] the dense-matching
        window: finer relief is noise.
    area_slope_a : float
        ``a`` of ``S ≥ a·A^-b`` (A in ha). [I] 0.025, the lower envelope for gully heads
        on Mediterranean cropland (Vandekerckhove et al. 2000).
    area_slope_b : float
        ``b`` of the threshold. [I] 0.4 (ibid.).
    min_channel_length_m : float
        A head's path must run in channel cells for at least half of this length, and a
        path joining another within it is a side branch of the same channel. [I] 10 m:
        2× the 5 m matching tolerance of the network validation.
    tall_object_m : float
        Cells standing more than max(this, the incision threshold) above the ground surface
        are tall objects (buildings, trees), left out of the detector's ground surface and
        head-scale reference (:func:`~kitegully.gully.relief.head_scale_relief`). [I] 2 m: twice the site's shrubs
        (Kamech ~1 m, Feurer et al. 2018), so shrubs on gully banks stay in the ground surface
        as before and buildings (3–6 m) and trees (4–7 m) leave it.
    """

    scale_m: float = 2.0
    relief_k: float = 3.0
    dsm_sigma_z_m: float = 0.05
    slope_window_m: float = 1.0
    area_slope_a: float = 0.025
    area_slope_b: float = 0.4
    min_channel_length_m: float = 10.0
    tall_object_m: float = 2.0

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any], measured_sigma_z_m: float | None = None) -> "HeadDetectionParams":
        """Build from ``gully.automatic_heads`` (keys of the same names); InputError on a bad value.

        ``dsm_sigma_z_m: null`` takes ``measured_sigma_z_m`` (the DSM's own noise at the
        checkpoints, :func:`~kitegully.gully.relief.dsm_noise_at_checkpoints`).
        """
        missing = [k for k in cls.__dataclass_fields__ if k not in cfg]
        if missing:
            raise InputError(f"gully.automatic_heads: missing key(s) {', '.join(missing)}")
        cfg = dict(cfg)
        if cfg["dsm_sigma_z_m"] is None:
            if measured_sigma_z_m is None or not np.isfinite(measured_sigma_z_m):
                raise InputError("gully.automatic_heads.dsm_sigma_z_m: null needs checkpoints to measure the DSM noise")
            cfg["dsm_sigma_z_m"] = float(measured_sigma_z_m)
        vals = {k: float(cfg[k]) for k in cls.__dataclass_fields__}
        bad = [k for k, v in vals.items() if not v > 0]
        if bad:
            raise InputError(f"gully.automatic_heads: {', '.join(bad)} must be > 0")
        return cls(**vals)


@njit(cache=True)
def _accumulate(dirs, valid, offs, cell_area, recv, stack):
    """Contributing area (m²) of every cell along D8 ``dirs`` (Kahn order); fills ``recv`` (-1 on entry). O(n).

    ``recv`` and ``stack`` (n cells each) come from the caller in the narrowest index type that
    holds n, so that an 80 M-cell grid spends 4 rather than 8 bytes a cell on each.
    """
    h, w = dirs.shape
    n = h * w
    indeg = np.zeros(n, np.int32)
    for r in range(h):
        for c in range(w):
            d = dirs[r, c]
            if d == 255 or not valid[r, c]:
                continue
            rr = r + offs[d, 0]
            cc = c + offs[d, 1]
            if 0 <= rr < h and 0 <= cc < w and valid[rr, cc]:
                recv[r * w + c] = rr * w + cc
                indeg[rr * w + cc] += 1
    area = np.zeros(n)
    top = 0
    for i in range(n):
        if valid.flat[i]:
            area[i] = cell_area
            if indeg[i] == 0:
                stack[top] = i
                top += 1
    while top > 0:
        top -= 1
        i = stack[top]
        j = recv[i]
        if j >= 0:
            area[j] += area[i]
            indeg[j] -= 1
            if indeg[j] == 0:
                stack[top] = j
                top += 1
    return area.reshape(h, w)


@njit(cache=True)
def _heads(channel, recv, n_steps, min_frac):
    """Channel cells without a channel donor whose next ``n_steps`` cells are mostly channel."""
    n = channel.size
    has_donor = np.zeros(n, np.bool_)
    for i in range(n):
        if channel[i] and recv[i] >= 0:
            has_donor[recv[i]] = True
    out = np.zeros(n, np.bool_)
    for i in range(n):
        if not channel[i] or has_donor[i]:
            continue
        j = i
        hits = 0
        k = 0
        while k < n_steps and j >= 0:
            if channel[j]:
                hits += 1
            j = recv[j]
            k += 1
        if hits >= min_frac * n_steps:
            out[i] = True
    return out


def flow_accumulation(dirs: np.ndarray, cell_m: float, valid: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Contributing area (m², the cell included) along D8 codes of :mod:`kitegully.terrain.flow`.

    ``valid`` (default: every cell) marks the cells that hold area; code 255 cells
    (outlets, undrained) receive flow but pass none on. Returns the area raster (float64) and the
    flat index of each cell's receiver (-1: none; int32 below 2³¹ cells, else int64). O(n) time;
    memory 8 bytes a cell for the area and 4 for the receivers, and 8 more while it runs.

    Parameters
    ----------
    dirs : ndarray (H, W) uint8
        D8 codes (255 = outlet/nodata/undrained).
    cell_m : float
        Cell size (m).
    valid : ndarray (H, W) bool or None
        Cells that hold area; None: every cell.

    Returns
    -------
    area : ndarray (H, W) float64
        Contributing area (m²); 0 on cells that are not valid.
    recv : ndarray (H·W,) int32 or int64
        Flat index of each cell's receiver, -1 where there is none.
    """
    if valid is None:
        valid = np.ones(dirs.shape, dtype=np.bool_)
    index = np.int32 if dirs.size < np.iinfo(np.int32).max else np.int64
    recv = np.full(dirs.size, -1, index)
    area = _accumulate(np.ascontiguousarray(dirs, np.uint8), np.ascontiguousarray(valid, np.bool_), D8_OFFSETS,
                       float(cell_m**2), recv, np.empty(dirs.size, index))
    return area, recv


def detect_heads(
    z: np.ndarray,
    filled: np.ndarray,
    dirs: np.ndarray,
    grid: GridSpec,
    params: HeadDetectionParams,
    workers: int = 1,
    observed: np.ndarray | None = None,
    reference: HeadScaleGround | None = None,
) -> tuple[np.ndarray, dict[str, float]]:
    """Gully-head cells from the DEM alone (see the module docstring).

    Parameters
    ----------
    z : ndarray (H, W)
        DEM (m), NaN nodata (holes may be interpolated).
    filled : ndarray (H, W)
        Its depression-free version (the tracing surface).
    dirs : ndarray (H, W) uint8
        D8 codes on ``filled`` (255 = outlet/nodata/undrained).
    grid : GridSpec
        The grid.
    params : HeadDetectionParams
    workers : int
        FFT threads.
    observed : ndarray bool (H, W), optional
        Cells the DSM matched (before its holes were interpolated); default: the finite
        cells of ``z``. The incision map is made from these cells alone (normalised
        convolution), and no head is detected within one matching window of an unmatched
        cell (:func:`~kitegully.gully.relief.matched_cells`).
    reference : HeadScaleGround, optional
        :func:`~kitegully.gully.relief.head_scale_ground` of ``z`` on the ``observed`` cells (NaN elsewhere) with
        these ``params``, when the caller has it (the gully map's head snapping made it);
        its ground surface is taken (:func:`~kitegully.gully.relief.head_scale_relief`).

    Returns
    -------
    heads : ndarray int64
        Flat indices of the head cells, highest first.
    stats : dict
        Counts of incised and channel cells and candidates, for the log and summary.

    Notes
    -----
    O(n log n) for the FFT smoothings, O(n) for accumulation and candidate search,
    O(L) for the tracing. Memory: a few float32/float64 rasters.
    """
    cell = grid.cell
    valid = np.isfinite(z)
    observed = valid if observed is None else observed
    # [I] the incision is measured on what the DSM observed: an interpolated gap (tree crown, shadow) is a
    # smooth membrane from its rim, and its head-scale depth is the interpolation's, not the ground's; the
    # smoothings' normalised convolution leaves the unmatched cells out (the gap rule below keeps heads
    # off their rims as well)
    incised, threshold, rough = incision_map(np.where(observed, z, np.nan) if not observed.all() else z, cell,
                                             params, workers, tall_objects_out=True, reference=reference)
    # no head where the DSM was not matched: within one matching window of a gap, open water or the edge
    matched = matched_cells(observed, cell, params.slope_window_m)
    incised &= matched
    zsl = gaussian_smooth_fft(z, params.slope_window_m / cell, workers=workers)
    gy, gx = np.gradient(zsl, cell)
    slope = np.hypot(gx, gy)
    del zsl, gx, gy
    area, recv = flow_accumulation(dirs, cell, valid)
    # the area-slope threshold a · A^-b (A in ha) in place: at 80 M cells each float64 temporary is 0.64 GB
    with np.errstate(divide="ignore", invalid="ignore"):
        np.divide(area, 1e4, out=area)
        np.power(area, -params.area_slope_b, out=area)
        np.multiply(params.area_slope_a, area, out=area)
        steep = slope >= area
    del area, slope
    channel = (incised & steep & valid).ravel()
    n_steps = max(1, int(round(params.min_channel_length_m / cell)))
    cand = np.flatnonzero(_heads(channel, recv, n_steps, 0.5))
    if cand.size == 0:
        return cand, {"incised_cells": int(incised.sum()), "channel_cells": int(channel.sum()), "candidates": 0,
                      "relief_threshold_m": threshold, "surface_roughness_m": rough}
    fz = filled.ravel()[cand]
    cand = cand[np.argsort(-fz, kind="stable")]
    cells, _down, starts, ends = trace_paths(filled, cand, dirs)
    lengths = np.diff(starts) * cell  # cells before joining / ending (D8 steps ~ cell)
    joined_short = ((ends == END_MERGE) & (lengths < params.min_channel_length_m)) | (ends == END_ON_NETWORK)
    heads = cand[~joined_short]
    n_paths = heads.size
    heads = one_head_per_incision(heads, grid, FWHM_PER_SIGMA * params.scale_m)
    stats = {"incised_cells": int(incised.sum()), "channel_cells": int(channel.sum()), "candidates": int(cand.size),
             "heads": int(heads.size), "heads_within_scale": int(n_paths - heads.size),
             "relief_threshold_m": threshold, "surface_roughness_m": rough}
    log.info("automatic heads: %d incised cells, %d channel cells, %d candidates, %d heads (%d more within %.3g m "
             "of a higher one dropped)", stats["incised_cells"], stats["channel_cells"], stats["candidates"],
             stats["heads"], stats["heads_within_scale"], FWHM_PER_SIGMA * params.scale_m)
    return heads, stats


def one_head_per_incision(heads: np.ndarray, grid: GridSpec, radius_m: float) -> np.ndarray:
    """The heads with every head within ``radius_m`` of a kept one before it dropped (greedy, in the given order).

    [I] The head-scale depth map is the DSM seen through a Gaussian of σ_h (``scale_m``):
    two channel heads closer than its full width at half maximum (``FWHM_PER_SIGMA``·σ_h,
    4.7 m at 2 m; the usual resolution limit of a Gaussian blur) are one incision to it,
    found twice (the same reasoning that makes an automatic head within the 6 m snapping
    radius of a digitised one the same head, :func:`kitegully.gully.pipeline.new_heads`).
    Without this, neighbouring cells of
    one broad, flat-floored head (the foot of a tree row or plot boundary, a wide hollow)
    each start a D8 path, and those paths run side by side, 0.2 m apart, for tens of metres
    before they join: one channel counted several times, in the network and in its false
    positives. ``heads`` come highest first from :func:`detect_heads`, so the highest of a
    cluster is kept.

    Parameters
    ----------
    heads : ndarray int64
        Flat cell indices of the heads, in order of preference.
    grid : GridSpec
        Their grid.
    radius_m : float
        Heads closer than this to a kept head are dropped.

    Returns
    -------
    ndarray int64
        The kept heads, in their order. O(k log k) for k heads.
    """
    heads = np.asarray(heads, dtype=np.int64)
    if heads.size < 2:
        return heads
    xs, ys = grid.cell_centres()
    r, c = np.divmod(heads, grid.width)
    xy = np.column_stack([xs[c], ys[r]])
    tree = cKDTree(xy)
    dropped = np.zeros(heads.size, dtype=bool)
    for i in range(heads.size):
        if dropped[i]:
            continue
        near = np.asarray(tree.query_ball_point(xy[i], radius_m), dtype=np.int64)
        dropped[near[near > i]] = True
    return heads[~dropped]


@njit(cache=True)
def _sustained(incised, dirs, offs, n_steps, min_hits):
    h, w = incised.shape
    out = np.zeros((h, w), np.bool_)
    for r in range(h):
        for c in range(w):
            if not incised[r, c]:
                continue
            rr, cc, hits = r, c, 0
            for _k in range(n_steps):
                if incised[rr, cc]:
                    hits += 1
                d = dirs[rr, cc]
                if d == 255:
                    break
                rr += offs[d, 0]
                cc += offs[d, 1]
                if rr < 0 or cc < 0 or rr >= h or cc >= w:
                    break
            out[r, c] = hits >= min_hits
    return out


def channel_entries(incised: np.ndarray, dirs: np.ndarray, cell_m: float, length_m: float) -> np.ndarray:
    """Incised cells whose D8 path stays in incised cells over at least half of ``length_m`` below them.

    [I] The snapping candidates of ``head_snap: incision``: a digitised head marks the
    upstream end of a channel, so the cell it is moved to must lead into one. A tillage
    furrow, the foot of a plant or a patch of matching noise is incised at head scale too,
    but flow from it leaves the incision within a few metres; the test is the automatic
    detector's (step 4 above: ``min_channel_length_m``, 2 × the 5 m matching tolerance).
    O(m·L/cell) for m incised cells.

    Parameters
    ----------
    incised : ndarray (H, W) bool
        Incised cells.
    dirs : ndarray (H, W) uint8
        D8 codes (255 = outlet/nodata/undrained).
    cell_m : float
        Cell size (m).
    length_m : float
        Length of the path tested (m), taken as a whole number of D8 steps (at least one).

    Returns
    -------
    ndarray (H, W) bool
    """
    n_steps = max(1, int(round(length_m / cell_m)))
    return _sustained(np.ascontiguousarray(incised, np.bool_), np.ascontiguousarray(dirs, np.uint8), D8_OFFSETS,
                      n_steps, int(np.ceil(0.5 * n_steps)))


def automatic_head_params(heads: str, cfg: Mapping[str, Any], dem: np.ndarray, grid: GridSpec,
                          checkpoints_csv: str | None = None, head_snap: str = "",
                          needed: bool = False) -> "HeadDetectionParams | None":
    """Parameters of the automatic head detection (None for ``digitised`` heads not snapped by ``incision``).

    ``head_snap: incision`` uses the detector's incision map (:func:`~kitegully.gully.relief.incision_map`) for the
    digitised heads too, so it needs these parameters whatever ``gully.heads`` is.

    Parameters
    ----------
    heads : str
        ``gully.heads``: ``digitised``, ``automatic`` or ``both``.
    head_snap : str
        ``gully.head_snap``.
    cfg : mapping
        The ``gully.automatic_heads`` section.
    dem, grid : array and GridSpec
        The mapping DEM.
    checkpoints_csv : str, optional
        Observed checkpoints; with ``dsm_sigma_z_m: null`` the DSM noise is measured there.
    needed : bool
        The parameters are needed whatever the heads (``gully.crowns``: ground surface and
        height threshold of the crown mask).

    Returns
    -------
    HeadDetectionParams or None
    """
    if heads == "digitised" and head_snap not in ("incision", "relief", "posterior") and not needed:
        return None
    sz = None
    if checkpoints_csv:
        from kitegully.evaluate.dem import read_checkpoints

        sz = dsm_noise_at_checkpoints(dem, grid, read_checkpoints(checkpoints_csv))
        log.info("DSM noise at the checkpoints (automatic heads): SD %.3f m", sz)
    return HeadDetectionParams.from_config(cfg, sz)
