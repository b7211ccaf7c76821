"""The head-scale relief of a DEM: how deep each cell lies below the ground around it.

The concavity step of the gully-head detector (:mod:`kitegully.gully.heads`, step 1) and of
the snapping of digitised heads (:mod:`kitegully.gully.network`): the ground surface with the
objects that stand on it removed (:func:`ground_surface`), the depth below it at the scale of
a head (:func:`head_scale_relief`, shared by two callers through :func:`head_scale_ground`),
and the thresholds that make that depth an incision: the DSM's noise at the checkpoints
(:func:`dsm_noise_at_checkpoints`) and the surface's own roughness (:func:`surface_roughness`),
combined in :func:`incision_map`; :func:`matched_cells` and :func:`visible_incisions` say where
an incision can be trusted.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import scipy.ndimage as ndi

from kitegully.evaluate.dem import nmad
from kitegully.io.raster import GridSpec
from kitegully.terrain.smoothing import gaussian_smooth_fft

if TYPE_CHECKING:
    import pandas as pd

    from kitegully.gully.heads import HeadDetectionParams

log = logging.getLogger(__name__)


def incision_map(z: np.ndarray, cell_m: float, params: HeadDetectionParams, workers: int = 1,
                 roughness: bool = True, tall_objects_out: bool = False,
                 reference: HeadScaleGround | None = None) -> tuple[np.ndarray, float, float]:
    """Incised cells: head-scale depth below the ground surface ≥ ``relief_k``·max(σ_z, ρ) (step 1 of :mod:`kitegully.gully.heads`).

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
