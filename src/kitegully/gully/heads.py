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
   robust spread of that depth map over the site, :func:`surface_roughness`: tillage
   furrows and crop rows of a photogrammetric DSM are not gullies). The smoothed surface is
   that of the DEM without raised objects (:func:`ground_surface`): on a DSM the ground at
   the foot of hedgerows and shrub rows otherwise looks incised at head scale. For the
   detector, tall objects (buildings, trees) are left out of that ground surface and of
   the Gaussian: the noise smoothing's skirt around them otherwise lifts the reference on a
   ring around each (:func:`head_scale_relief`).
2. Flow: D8 directions on the filled DEM, contributing area A (m²), slope S along the
   flow measured over the DSM's resolution.
3. Channel cells: incised cells with ``S ≥ a·A_ha^-b``.
   No channel cell within one matching window of a DSM gap (:func:`matched_cells`).
4. Heads: channel cells with no channel cell upstream whose path downstream stays in
   channel cells over most of ``min_channel_length_m`` (a channel, not a pit). Traced
   highest first; a candidate whose path joins one traced before within
   ``min_channel_length_m`` is a bank-side twin of that channel and is dropped, and so is
   one within the head-scale Gaussian's FWHM of a higher head (:func:`one_head_per_incision`).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Mapping

import numpy as np
import scipy.ndimage as ndi
from numba import njit
from scipy.spatial import cKDTree

from kitegully import InputError
from kitegully.evaluate.dem import nmad
from kitegully.io.raster import GridSpec
from kitegully.terrain.flow import D8_OFFSETS, END_MERGE, END_ON_NETWORK, trace_paths
from kitegully.terrain.smoothing import gaussian_smooth_fft

if TYPE_CHECKING:
    import pandas as pd

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
        roughness) (:func:`surface_roughness`). [I] 3, as the operator's visibility rule
        (a 3σ step).
    dsm_sigma_z_m : float
        Vertical noise of the DSM (m). [I] ``null`` in the config = the SD of DSM minus
        the RTK checkpoints (:func:`dsm_noise_at_checkpoints`): the DSM's own noise where
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
        head-scale reference (:func:`head_scale_relief`). [I] 2 m: twice the site's shrubs
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
        checkpoints, :func:`dsm_noise_at_checkpoints`).
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
        cell (:func:`matched_cells`).
    reference : HeadScaleGround, optional
        :func:`head_scale_ground` of ``z`` on the ``observed`` cells (NaN elsewhere) with
        these ``params``, when the caller has it (the gully map's head snapping made it);
        its ground surface is taken (:func:`head_scale_relief`).

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


def incision_map(z: np.ndarray, cell_m: float, params: HeadDetectionParams, workers: int = 1,
                 roughness: bool = True, tall_objects_out: bool = False,
                 reference: HeadScaleGround | None = None) -> tuple[np.ndarray, float, float]:
    """Incised cells: head-scale depth below the ground surface ≥ ``relief_k``·max(σ_z, ρ) (step 1 above).

    With ``roughness=False`` the threshold is ``relief_k``·σ_z alone: the operator's
    visibility rule, for snapping digitised heads (:func:`kitegully.gully.network.snap_heads`,
    ``incision``). [I] The detector must reject tillage furrows anywhere on the site, hence
    ρ; a digitised head marks a place where a person saw an incision, which by the
    visibility rule is relief ≥ 3σ_z, and the operator places the head where the incision
    becomes visible, i.e. near that threshold, so a threshold raised to 3ρ would leave the
    upstream end of the incision (the head itself) out of the map.

    Parameters
    ----------
    z : ndarray (H, W)
        DEM (m), NaN nodata.
    cell_m : float
        Cell size (m).
    params : HeadDetectionParams
        ``scale_m``, ``relief_k``, ``dsm_sigma_z_m`` and ``slope_window_m`` are used.
    workers : int
        FFT threads.
    roughness : bool
        Threshold on max(σ_z, ρ) (the detector) or on σ_z alone (the operator's visibility rule).
    tall_objects_out : bool
        Tall objects left out of the reference surface (:func:`head_scale_relief`; the detector).
    reference : HeadScaleGround, optional
        :func:`head_scale_ground` of this ``z`` and ``params``, when the caller has it.

    Returns
    -------
    incised : ndarray bool (H, W)
    threshold : float
        The depth threshold (m).
    roughness : float
        ρ, the surface's own head-scale roughness (m, :func:`surface_roughness`).

    Notes
    -----
    O(n log n): three FFT smoothings and the opening of :func:`ground_surface` (five and two
    with ``tall_objects_out``).
    """
    valid = np.isfinite(z)
    relief, rough = head_scale_relief(z, cell_m, params, workers, tall_objects_out=tall_objects_out, reference=reference)
    threshold = params.relief_k * (max(params.dsm_sigma_z_m, rough) if roughness else params.dsm_sigma_z_m)
    incised = np.zeros(z.shape, bool)
    incised[valid] = relief[valid] >= threshold
    log.info("incised where the head-scale depth >= %.3g m = %.3g x %s(DSM noise %.3g m, surface roughness %.3g m): "
             "%d cells", threshold, params.relief_k, "max" if roughness else "(roughness not used)",
             params.dsm_sigma_z_m, rough, int(incised.sum()))
    return incised, float(threshold), float(rough)


@dataclass
class HeadScaleGround:
    """:func:`head_scale_ground` of one DEM, handed from one head-scale relief to the next.

    Attributes
    ----------
    ground : ndarray (H, W) float32 or None
        :func:`ground_surface` of the DEM; None once a tall-object relief has taken it.
    rough : float
        ρ, :func:`surface_roughness` of the plain head-scale depth map (m).
    """

    ground: np.ndarray | None
    rough: float

    def take(self) -> np.ndarray:
        """The ground surface, released from this holder (its last use frees it)."""
        if self.ground is None:
            raise ValueError("the ground surface was already taken by a tall-object relief")
        ground, self.ground = self.ground, None
        return ground


def head_scale_ground(z: np.ndarray, cell_m: float, params: HeadDetectionParams,
                      workers: int = 1) -> HeadScaleGround:
    """The ground surface ``Z₀`` and the roughness ρ of :func:`head_scale_relief`, for reuse.

    The gully map needs the head-scale relief twice on the same DEM: plain, to snap the
    digitised heads and find edge inlets, and without tall objects, for the detector. Both
    start from this ground surface and this ρ (three of the detector's six FFT smoothings;
    about 20 s of the gully map's 123 s at 80 M cells, session 38), so the map computes them
    once and hands them to both (``reference``). O(n log n).

    Parameters
    ----------
    z : ndarray (H, W)
        DEM (m), NaN nodata: the same array the relief will be made from.
    cell_m : float
        Cell size (m).
    params : HeadDetectionParams
        ``scale_m`` and ``slope_window_m`` are used.
    workers : int
        FFT threads.

    Returns
    -------
    HeadScaleGround
        :func:`ground_surface` of ``z`` (NaN where ``z`` is) and ρ.
    """
    valid = np.isfinite(z)
    # roughness: the DSM's own head-scale micro-relief (furrows, crop rows), as the operator sees it
    rough = surface_roughness((gaussian_smooth_fft(z, params.scale_m / cell_m, workers=workers) - z)[valid])
    return HeadScaleGround(ground_surface(z, cell_m, params.scale_m, params.slope_window_m, workers), rough)


def head_scale_relief(z: np.ndarray, cell_m: float, params: HeadDetectionParams,
                      workers: int = 1, tall_objects_out: bool = False,
                      reference: HeadScaleGround | None = None) -> tuple[np.ndarray, float]:
    """Head-scale depth below the ground surface, ``G_σh ∗ Z₀ − Z`` (m, NaN nodata), and the roughness ρ.

    ``Z₀`` is :func:`ground_surface` (objects standing on the ground removed), σh =
    ``scale_m``. A plane is kept exactly by the Gaussian (relief 0 on any slope), a field's
    curvature κ adds only about κσh² (0.04 m at κ 0.01 m⁻¹ and σh 2 m), vegetation stands
    above the ground (negative relief), and an incision narrower than ~2σh shows at nearly
    its full depth. ρ is :func:`surface_roughness` of the plain head-scale depth map.

    With ``tall_objects_out`` the cells of ``Z`` standing more than max(``tall_object_m``,
    ``relief_k``·max(σ_z, ρ)) above ``Z₀`` (buildings, trees) are left out of a second
    ``Z₀`` made without them and of the Gaussian (normalised convolution, first-order
    corrected at the holes' edges). [I] The ground surface's noise smoothing (σ =
    ``slope_window_m``) spreads a wall or a crown's edge over the 2–3 m beside it and the
    opening keeps that skirt, so the head-scale reference stands high on a ring around every
    building and tree row: constructed, a ring of up to 0.17–0.28 m around 10–16 m buildings
    4–5 m high on a 10 % slope (threshold 0.15 m), 0.03 m with them left out. On four twins'
    DSMs, 10 of the 14 false automatic heads with the longest false paths sat on such rings
    (session 37, docs/stages/06_gully.md). Shrubs (below ``tall_object_m``) stay: leaving
    them out as well lowered the relief of true heads in shrub strips (good fit −2.8 points
    over 24 twins).

    ``reference`` is :func:`head_scale_ground` of this same ``z`` and ``params``, computed
    here when None; the result is the same bit for bit. The tall-object relief is its last
    use: it takes the ground surface out of ``reference`` (:meth:`HeadScaleGround.take`), so
    that the first surface is freed before the second is made (0.32 GB at 80 M cells, where
    the gully map's memory peaks).
    O(n log n): a second :func:`ground_surface`.

    Parameters
    ----------
    z : ndarray (H, W)
        DEM (m), NaN nodata.
    cell_m : float
        Cell size (m).
    params : HeadDetectionParams
        ``scale_m`` and ``slope_window_m`` are used; with ``tall_objects_out`` also ``tall_object_m``,
        ``relief_k`` and ``dsm_sigma_z_m``.
    workers : int
        FFT threads.
    tall_objects_out : bool
        Leave tall objects out of the ground surface and the Gaussian.
    reference : HeadScaleGround or None
        :func:`head_scale_ground` of this ``z`` and ``params``; None: computed here.

    Returns
    -------
    relief : ndarray (H, W) float32
        Head-scale depth (m), NaN where ``z`` is NaN.
    rough : float
        ρ (m).
    """
    valid = np.isfinite(z)
    if reference is None:
        reference = head_scale_ground(z, cell_m, params, workers)
    ground = reference.take() if tall_objects_out else reference.ground
    rough = reference.rough
    del reference
    if tall_objects_out:
        height = max(params.tall_object_m, params.relief_k * max(params.dsm_sigma_z_m, rough))
        tall = standing_above(z, ground, height)
        del ground
        # float32: what the ground surface's FFT smoothings work in anyway (half a float64 copy at 80 M cells)
        without = z.astype(np.float32)
        without[tall] = np.nan
        ground = ground_surface(without, cell_m, params.scale_m, params.slope_window_m, workers)
        del without
        tall |= standing_above(z, ground, height)
        ground[tall] = np.nan
        log.info("head-scale reference: %d cells stand more than %.3g m above the ground (tall objects), left out",
                 int(tall.sum()), height)
        del tall
    zs = gaussian_smooth_fft(ground, params.scale_m / cell_m, workers=workers)
    del ground
    relief = np.where(valid, zs - z, np.nan).astype(np.float32)
    return relief, rough


def standing_above(z: np.ndarray, ground: np.ndarray, height_m: float, rows: int = 1024) -> np.ndarray:
    """Cells where ``z`` stands more than ``height_m`` above ``ground`` (objects; NaN in either: no).

    Row blocks keep the difference's temporaries to ``rows`` rows (a whole-grid float64
    difference is 0.64 GB at 80 M cells). O(n).

    Parameters
    ----------
    z, ground : ndarray (H, W)
        A surface and the ground surface beneath it (m).
    height_m : float
        Height above the ground (m).
    rows : int
        Rows per block.

    Returns
    -------
    ndarray bool (H, W)
    """
    out = np.zeros(z.shape, dtype=bool)
    with np.errstate(invalid="ignore"):
        for i in range(0, z.shape[0], rows):
            np.greater(z[i:i + rows] - ground[i:i + rows], height_m, out=out[i:i + rows])
    return out


def matched_cells(observed: np.ndarray, cell_m: float, window_m: float) -> np.ndarray:
    """Observed cells farther than one matching window from any unobserved cell or the grid edge.

    [I] A photogrammetric DSM has gaps where dense matching failed (low texture, shadow,
    occlusion, open water); the cells at a gap's rim were matched with part of their
    correlation window on the failing surface, and the surface across an interpolated gap
    is a guess whose edges bend the head-scale relief. Automatic heads there are not
    evidence of a channel: on the six ensemble DSMs half of the false automatic heads lay
    within 1 m of nodata, against 5 % of the true ones (``benchmarks/gully_auto_fp_analysis.py``).
    The margin is the matching window (``slope_window_m``, 1 m: 5 × 5 cells at 0.2 m), the
    DSM's own resolution. O(n) (exact Euclidean distance transform).

    Parameters
    ----------
    observed : ndarray (H, W) bool
        Cells the DSM matched.
    cell_m : float
        Cell size (m).
    window_m : float
        The matching window (m).

    Returns
    -------
    ndarray (H, W) bool
    """
    import cv2

    src = np.pad(np.asarray(observed, bool).astype(np.uint8), 1)
    dist = cv2.distanceTransform(src, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)[1:-1, 1:-1] * cell_m
    return dist > window_m


def visible_incisions(incised: np.ndarray, cell_m: float, window_m: float) -> np.ndarray:
    """Incised cells in 8-connected patches of at least ``3·window_m × window_m`` (a line, not a dot).

    [I] What an operator digitises as a head on the hillshade is an incision that runs as a
    line over at least three resolution cells of the DSM (the twin's visibility rule,
    ``survey.heads_visibility.min_run_cells`` 3); the DSM's resolution is its dense-matching
    window (``slope_window_m``, 1 m). A patch smaller than three windows is a dot: matching
    noise or a single plant gap, not the incision a head was digitised on. O(n).

    Parameters
    ----------
    incised : ndarray (H, W) bool
        Incised cells.
    cell_m : float
        Cell size (m).
    window_m : float
        The matching window (m).

    Returns
    -------
    ndarray (H, W) bool
        The incised cells of the patches kept.
    """
    lab, n = ndi.label(incised, structure=np.ones((3, 3), bool))
    if n == 0:
        return np.zeros(incised.shape, bool)
    size = np.bincount(lab.ravel(), minlength=n + 1)
    keep = size * cell_m**2 >= 3.0 * window_m**2
    keep[0] = False
    return keep[lab]


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


def ground_surface(z: np.ndarray, cell_m: float, scale_m: float, noise_window_m: float, workers: int = 1) -> np.ndarray:
    """The DEM without the objects that stand on the ground, as reference of the head-scale depth map.

    ``Z_L + open(Z_n − Z_L)``: ``Z_n`` the DEM smoothed at ``noise_window_m``, ``Z_L`` the DEM
    smoothed at ``4·scale_m`` (the local slope and field-scale relief), ``open`` a grey
    opening (erosion then dilation) with a square of side ``4·scale_m + 6·noise_window_m``.
    NaN where ``z`` is NaN.

    [I] On a photogrammetric DSM, shrubs, hedgerows and tree rows stand above the ground; a
    Gaussian of σ = ``scale_m`` spreads them over ±2σ, so the ground at their foot looks
    incised (most automatic heads on the default twin's DSM sat at the upslope foot of
    hedgerows). An opening removes raised objects narrower than its element and keeps
    valleys (gullies are concave: untouched) and level planes; made on the relief about the
    local slope (``Z_n − Z_L``), its flat element lies along the slope, as the ``plane``
    head snapping does, so that on a sloping field it does not keep the flanks of an object.
    The element spans the Gaussian's ±2σ support plus the ±3σ widening of the noise smoothing;
    the noise smoothing (σ = the matching window) keeps the opening from sinking the
    surface to the noise's lower envelope. O(n log n) for two FFT smoothings, O(n·k) for
    the separable min/max filters (k cells across the element).

    Parameters
    ----------
    z : ndarray (H, W)
        DEM (m), NaN nodata.
    cell_m : float
        Cell size (m).
    scale_m : float
        σh of the head-scale depth map (m).
    noise_window_m : float
        σ of the noise smoothing (m); 0: no noise smoothing.
    workers : int
        FFT threads.

    Returns
    -------
    ndarray (H, W) float32
        The ground surface (m).
    """
    valid = np.isfinite(z)
    zn = gaussian_smooth_fft(z, noise_window_m / cell_m, workers=workers) if noise_window_m > 0 else np.asarray(z)
    zl = gaussian_smooth_fft(z, 4.0 * scale_m / cell_m, workers=workers)
    k = 2 * max(1, int(round((2.0 * scale_m + 3.0 * noise_window_m) / cell_m))) + 1
    r = np.where(valid, zn - zl, np.inf).astype(np.float32)
    er = ndi.minimum_filter(r, size=k, mode="nearest")
    er[~valid | ~np.isfinite(er)] = -np.inf
    op = ndi.maximum_filter(er, size=k, mode="nearest")
    out = (zl + op).astype(np.float32)
    out[~valid] = np.nan
    return out


def surface_roughness(relief: np.ndarray) -> float:
    """Robust spread (NMAD, m) of the head-scale depth map over the DSM: the surface's own micro-relief.

    [I] The checkpoints measure the DSM's noise on bare, smooth ground; a photogrammetric
    surface of fields also carries tillage furrows, crop rows and the gaps between plants,
    which show in the head-scale depth map as incisions of up to a few decimetres. Gullies
    cover a few per cent of a site, so the median absolute deviation of that map over all
    cells (× 1.4826, the SD of a normal background) is the spread of the ungullied surface;
    an incision must stand out from that as well as from the noise. O(n).
    """
    spread = nmad(np.asarray(relief, dtype=np.float64).ravel())
    return 0.0 if np.isnan(spread) else spread


def dsm_noise_at_checkpoints(dsm: np.ndarray, grid: GridSpec, points: pd.DataFrame,
                             outlier_nmad: float | None = 4.0) -> float:
    """The DSM's noise σ_z (m): SD of DSM minus checkpoint elevation, blunders left out.

    [I] A checkpoint more than ``outlier_nmad`` NMADs from the median error lies on a gross
    matching error (metres at one spot), not on the DSM's noise, and is left out
    (:func:`kitegully.evaluate.dem.sd_without_blunders`, the change stage's rule): on a held-out
    twin one 5.3 m blunder among 466 checkpoints made a plain SD of 0.35 m out of an NMAD of
    0.057 m, and the incision threshold 3·σ_z then hid every head. O(n log n) for n points.

    Parameters
    ----------
    dsm : ndarray (H, W)
        The DSM (m), NaN nodata.
    grid : GridSpec
    points : DataFrame
        ``x, y, z`` of the observed RTK checkpoints on open ground.
    outlier_nmad : float or None
        Blunder distance in NMADs (None: the plain SD of all).

    Returns
    -------
    float
        σ_z; NaN when fewer than 2 checkpoints fall on valid cells.
    """
    from kitegully.evaluate.dem import checkpoint_errors, sd_without_blunders

    e = checkpoint_errors(dsm, grid, points)["error_m"].to_numpy()
    sd, kept = sd_without_blunders(e, outlier_nmad)
    if kept.size and not kept.all():
        log.info("DSM noise at the checkpoints: %d of %d are blunders (> %g NMAD from the median) and left out: "
                 "sigma_z %.3f m (SD of all %.3f m)", int((~kept).sum()), kept.size, outlier_nmad, sd,
                 float(np.nanstd(e, ddof=1)))
    return sd


def automatic_head_params(heads: str, cfg: Mapping[str, Any], dem: np.ndarray, grid: GridSpec,
                          checkpoints_csv: str | None = None, head_snap: str = "",
                          needed: bool = False) -> "HeadDetectionParams | None":
    """Parameters of the automatic head detection (None for ``digitised`` heads not snapped by ``incision``).

    ``head_snap: incision`` uses the detector's incision map (:func:`incision_map`) for the
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
