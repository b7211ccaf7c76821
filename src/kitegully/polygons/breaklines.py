"""Breaklines: convex upper gully edges from Wood's bivariate quadratic (Höfle et al. 2013 sect. 4.1).

The surface in an n × n window is fitted by least squares with
``z = a x² + b y² + c xy + d x + e y + f`` (x east, y north, metres, origin at the
window centre). On a regular grid the design matrix is the same for every window, so
each coefficient is a fixed linear combination of the window's values: a correlation
kernel, applied as a sum of separable 1-D passes (SVD of the kernel, rank ≤ 3).

Curvatures, signed so that **positive = convex** (the surface bends down, as at the upper
edge of a gully or on a ridge; a valley floor is negative or zero):

``maximum``
    Wood's maximum (convex) curvature ``-a - b + sqrt((a - b)² + c²)`` (1/m), the
    largest downward bending in any direction (GRASS ``r.param.scale method=maxic``).
``plan``
    Plan (contour) curvature ``-2 (b d² + a e² - c d e) / (d² + e²)^1.5`` (1/m); GRASS
    ``r.param.scale method=planc`` has the opposite sign (negative on ridges). Plan
    curvature is identically zero across a *straight* edge, where the contours run
    parallel to it (shown in the tests), and it grows without bound where the slope
    goes to zero; it only picks up edges that bend in plan.
``profile``
    Profile curvature ``-2 (a d² + b e² + c d e) / ((d² + e²)(1 + d² + e²)^1.5)`` (1/m),
    the bending along the slope line (GRASS ``profc``).
"""

from __future__ import annotations

import logging

import numpy as np
import scipy.ndimage as ndi
from skimage.morphology import remove_small_objects, skeletonize

from kitegully import InputError
from kitegully.terrain.holes import fill_nearest

log = logging.getLogger(__name__)

#: Curvature types (``polygons.breaklines.curvature``).
CURVATURES = ("maximum", "plan", "profile")


def quadratic_kernels(window: int, cell: float) -> np.ndarray:
    """Least-squares correlation kernels of the coefficients (a, b, c, d, e, f).

    Parameters
    ----------
    window : int
        Odd window side in cells (≥ 3).
    cell : float
        Cell size (m).

    Returns
    -------
    ndarray (6, window, window)
        ``coef_k = Σ kernel_k · z_window`` (row 0 of the window is its north edge).
    """
    if window < 3 or window % 2 == 0:
        raise ValueError(f"window must be odd and >= 3, got {window}")
    h = window // 2
    off = np.arange(-h, h + 1) * cell
    y, x = np.meshgrid(-off, off, indexing="ij")  # rows go south: y = -row offset
    x, y = x.ravel(), y.ravel()
    X = np.column_stack([x * x, y * y, x * y, x, y, np.ones_like(x)])
    K = np.linalg.pinv(X)  # (6, n²)
    return K.reshape(6, window, window)


def _correlate_separable(z: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    u, s, vt = np.linalg.svd(kernel)
    out = np.zeros_like(z)
    for i in range(len(s)):
        if s[i] <= 1e-10 * s[0]:
            break
        tmp = ndi.correlate1d(z, u[:, i] * s[i], axis=0, mode="nearest")
        out += ndi.correlate1d(tmp, vt[i], axis=1, mode="nearest")
    return out


def quadratic_coefficients(z: np.ndarray, cell: float, window: int) -> tuple[np.ndarray, ...]:
    """Coefficients (a, b, c, d, e) of the windowed quadratic at every cell.

    NaN cells are filled with the nearest valid value for the fit and every coefficient
    is NaN where the window holds a NaN cell. O(H·W·window·rank).

    Parameters
    ----------
    z : ndarray (H, W)
        DEM (m), NaN nodata.
    cell : float
        Cell size (m).
    window : int
        Odd window side in cells (≥ 3).

    Returns
    -------
    a, b, c, d, e : ndarray (H, W) float64
        Coefficients at every cell (x east, y north): ``a, b, c`` in 1/m, ``d, e`` the slopes (m/m).
    """
    z = np.asarray(z, dtype=np.float64)
    nan = ~np.isfinite(z)
    if nan.all():
        raise InputError("polygons: the DEM is all nodata")
    zf = fill_nearest(z)
    # centre on the mean for numerical accuracy of the constant term
    zf = zf - np.nanmean(z)
    kernels = quadratic_kernels(window, cell)
    bad = ndi.maximum_filter(nan, size=window, mode="nearest") if nan.any() else None
    out = []
    for k in range(5):
        c = _correlate_separable(zf, kernels[k])
        if bad is not None:
            c[bad] = np.nan
        out.append(c)
    return tuple(out)


def ground_opening(z: np.ndarray, cell: float, segment_m: float) -> np.ndarray:
    """The DEM without raised objects narrower than ``segment_m``: 2-D grey opening with a flat disc.

    The disc's diameter is ``segment_m`` (an odd number of cells, at least 3); NaN cells are
    filled with the nearest valid value first (and stay filled: the result only steers the
    upper-edge test). Removes shrub clumps and hedge crowns narrower than the disc, keeps
    concave forms (gullies) and planes; at a convex edge it bevels the corner (by up to
    the along-edge gradient × the disc radius), so it is used for the *direction* across
    an edge only (:func:`_edge_profiles`). O(n · k²) for k cells across the disc.

    Parameters
    ----------
    z : ndarray (H, W)
        DEM (m), NaN nodata.
    cell : float
        Cell size (m).
    segment_m : float
        Diameter of the disc (m).

    Returns
    -------
    ndarray (H, W) float64
        The opened DEM (m), without NaN.
    """
    k = max(3, 2 * int(round(0.5 * segment_m / cell)) + 1)
    h = k // 2
    yy, xx = np.mgrid[-h:h + 1, -h:h + 1]
    disc = xx * xx + yy * yy <= h * h + 1e-9
    zf = fill_nearest(np.asarray(z, dtype=np.float64))
    return ndi.grey_opening(zf, footprint=disc, mode="nearest")


def _edge_profiles(z: np.ndarray, cell: float, window: int, rr: np.ndarray, cc: np.ndarray, ground_m: float = 0.0):
    """Direction of strongest convex bending at cells (rr, cc) and the DEM sampled across it.

    Returns (vx, vy, z0, near_p, far_p, near_m, far_m): unit vector (x east, y north) of
    the eigenvector of the quadratic's Hessian with the most negative eigenvalue, the cell
    elevation, and bilinear samples at +r/2, +r, -r/2, -r along it (r = half the window).

    With ``ground_m`` > 0 both are taken on the ground instead of the DEM: the direction
    from the quadratic fitted to the 2-D opening of the DEM with a disc of that diameter
    (:func:`ground_opening`; a clump on a rim no longer turns it), the samples from the DEM's
    profile along that direction from -(r + ground_m) to +(r + ground_m), opened in 1-D with
    a ``ground_m`` segment (:func:`kitegully.polygons.profiles.ground_profile`'s filter:
    removes bumps narrower than the segment, keeps a step edge and a straight slope exactly,
    and, being across the edge, is not biased by the edge's own gradient along its length).
    O(m · (r + ground_m) / cell) for m cells.
    """
    zd = ground_opening(z, cell, ground_m) if ground_m > 0 else z
    a, b, c, _, _ = quadratic_coefficients(zd, cell, window)
    a, b, c = a[rr, cc], b[rr, cc], c[rr, cc]
    # Hessian [[2a, c], [c, 2b]] in (x east, y north); eigenvector of the smaller eigenvalue
    lam = (a + b) - np.sqrt((a - b) ** 2 + c**2)
    vx, vy = c, lam - 2 * a
    small = np.hypot(vx, vy) < 1e-12
    vx, vy = np.where(small, lam - 2 * b, vx), np.where(small, c, vy)
    small = np.hypot(vx, vy) < 1e-12
    vx, vy = np.where(small, 1.0, vx), np.where(small, 0.0, vy)
    n = np.hypot(vx, vy)
    vx, vy = vx / n, vy / n
    r = (window // 2) * cell
    zf = np.where(np.isfinite(z), z, np.nanmin(z))
    if ground_m > 0:
        n_half = int(np.ceil((r + ground_m) / cell))
        s = np.arange(-n_half, n_half + 1) * cell  # metres along the profile, 0 at the cell
        prof = ndi.map_coordinates(zf, [(rr[:, None] - s[None, :] * vy[:, None] / cell).ravel(),
                                        (cc[:, None] + s[None, :] * vx[:, None] / cell).ravel()],
                                   order=1, mode="nearest").reshape(len(rr), len(s))
        k = int(round(ground_m / cell)) + 1
        if len(rr) and k >= 2:
            prof = ndi.grey_opening(prof, size=(1, k), mode="nearest")
        i0 = n_half

        def at(dist):
            return prof[:, i0 + int(round(dist / cell))] if len(rr) else np.zeros(0)

        # the opened profile at the cell itself: its ground (a clump on the rim is removed)
        return vx, vy, at(0.0), at(0.5 * r), at(r), at(-0.5 * r), at(-r)

    def side(sign, dist):  # rows go south: a step vy north is -vy / cell rows
        return ndi.map_coordinates(zf, [rr - sign * dist * vy / cell, cc + sign * dist * vx / cell], order=1, mode="nearest")

    return vx, vy, zf[rr, cc], side(1, 0.5 * r), side(1, r), side(-1, 0.5 * r), side(-1, r)


def upper_edge_mask(z: np.ndarray, cell: float, window: int, threshold: float, candidates: np.ndarray,
                    ground_m: float = 0.0) -> np.ndarray:
    """Which candidate cells are upper edges (level ground on one side) rather than ridges.

    Across the direction of strongest convex bending (eigenvector of the fitted quadratic's
    Hessian with the most negative eigenvalue) the DEM is sampled at ± r/2 and ± r, r = half
    the window. An upper edge has level ground on one side, within ``δ = threshold · r² / 2``
    of the cell at r/2 and r (the drop of a surface bending at the threshold curvature over
    r), and drops by more than δ on the other; a ridge, such as the crown of a hedge or a
    tree in a DSM, drops by more than δ on both sides, and its flanks rise by more than δ
    to it.

    ``ground_m`` > 0: the test is made on the ground under plants narrower than ``ground_m``
    (:func:`_edge_profiles`): a shrub clump standing *on* a rim makes the DSM drop on both
    sides (into the gully and off the clump), i.e. a ridge, though the ground is an upper
    edge; a free-standing shrub or a hedge narrower than ``ground_m`` leaves level ground
    on both sides and is dropped as before; wider crowns stay ridges.

    Returns a boolean mask (subset of ``candidates``). O(candidates).

    Parameters
    ----------
    z : ndarray (H, W)
        DEM (m), NaN nodata.
    cell : float
        Cell size (m).
    window : int
        Odd window side (cells).
    threshold : float
        Curvature threshold (1/m).
    candidates : ndarray (H, W) bool
        Cells to test.
    ground_m : float
        Width of the widest plants to look under (m); 0 = test on the DEM.

    Returns
    -------
    ndarray (H, W) bool
        The candidate cells that are upper edges.
    """
    rr, cc = np.nonzero(candidates)
    _, _, z0, near_p, far_p, near_m, far_m = _edge_profiles(z, cell, window, rr, cc, ground_m)
    r = (window // 2) * cell
    delta = threshold * r * r / 2.0
    plus_high = near_p + far_p >= near_m + far_m
    hi_near, hi_far = np.where(plus_high, near_p, near_m), np.where(plus_high, far_p, far_m)
    lo_far = np.where(plus_high, far_m, far_p)
    keep = (np.abs(hi_near - z0) <= delta) & (np.abs(hi_far - z0) <= delta) & (lo_far < z0 - delta)
    out = np.zeros_like(candidates, dtype=bool)
    out[rr[keep], cc[keep]] = True
    return out


def low_sides(z: np.ndarray, cell: float, window: int, edges: np.ndarray,
              ground_m: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Breakline cells and the unit step (rows, cols) towards their lower side.

    Returns (rows, cols, d_row, d_col): for each cell of ``edges``, the direction across
    the edge in which the DEM (with ``ground_m`` > 0: the ground, as in :func:`upper_edge_mask`) falls
    (the incision side of an upper edge).

    Parameters
    ----------
    z : ndarray (H, W)
        DEM (m), NaN nodata.
    cell : float
        Cell size (m).
    window : int
        Odd window side (cells).
    edges : ndarray (H, W) bool
        Breakline cells.
    ground_m : float
        Width of the widest plants to look under (m); 0 = on the DEM.

    Returns
    -------
    rows, cols : ndarray int
        Row and column of each breakline cell.
    d_row, d_col : ndarray float
        Unit step (rows, cols) towards the lower side.
    """
    rr, cc = np.nonzero(edges)
    vx, vy, _, near_p, far_p, near_m, far_m = _edge_profiles(z, cell, window, rr, cc, ground_m)
    sign = np.where(near_p + far_p >= near_m + far_m, -1.0, 1.0)  # towards the lower side
    return rr, cc, -sign * vy, sign * vx


def convexity(z: np.ndarray, cell: float, window: int, kind: str = "maximum", min_slope: float = 1e-3) -> np.ndarray:
    """Curvature (1/m) of the windowed quadratic, positive where the surface is convex.

    Parameters
    ----------
    z : ndarray (H, W)
        DEM (m), NaN nodata.
    cell : float
        Cell size (m).
    window : int
        Odd window side (cells); 9 in the paper.
    kind : str
        One of :data:`CURVATURES`.
    min_slope : float
        Plan and profile curvature are set to 0 where the fitted slope is below this
        (undefined on a level surface).
    """
    if kind not in CURVATURES:
        raise ValueError(f"curvature must be one of {CURVATURES}, got {kind!r}")
    a, b, c, d, e = quadratic_coefficients(z, cell, window)
    if kind == "maximum":
        return -a - b + np.sqrt((a - b) ** 2 + c**2)
    g2 = d * d + e * e
    flat = g2 < min_slope**2
    g2s = np.where(flat, 1.0, g2)
    if kind == "plan":
        k = -2.0 * (b * d * d + a * e * e - c * d * e) / g2s**1.5
    else:
        k = -2.0 * (a * d * d + b * e * e + c * d * e) / (g2s * (1.0 + g2s) ** 1.5)
    return np.where(flat, 0.0, k)


def detect_breaklines(
    z: np.ndarray, cell: float, window: int, threshold: float, kind: str = "maximum", min_length_m: float = 0.0,
    upper_edges_only: bool = False, edge_ground_m: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Breakline raster: skeleton of the mask ``convexity > threshold``.

    Parameters
    ----------
    z : ndarray (H, W)
        DEM (m).
    cell : float
        Cell size (m).
    window : int
        Window side (cells).
    threshold : float
        Curvature threshold (1/m); 0.2 in the paper.
    kind : str
        Curvature type (:data:`CURVATURES`).
    min_length_m : float
        Skeleton pieces shorter than this (counted in cells × cell) are dropped.
    upper_edges_only : bool
        Drop ridge cells (:func:`upper_edge_mask`) before skeletonising.
    edge_ground_m : float
        Make that test on the ground under plants narrower than this (m); 0 = on the DEM.

    Returns
    -------
    skeleton : ndarray bool
        One-cell-wide breaklines.
    curvature : ndarray float32
        The convexity raster (1/m).
    """
    h, w = z.shape
    if h < window or w < window:
        raise InputError(f"polygons.breaklines.window_cells: the DEM ({h} x {w} cells) is smaller than the {window} x {window} window")
    k = convexity(z, cell, window, kind)
    mask = np.nan_to_num(k, nan=0.0) > threshold
    n_conv = int(mask.sum())
    if upper_edges_only:
        mask = upper_edge_mask(z, cell, window, threshold, mask, edge_ground_m)
        log.info("breaklines: %d of %d convex cells are upper edges (the rest ridges; tested on %s)", int(mask.sum()), n_conv,
                 f"the ground under plants < {edge_ground_m:g} m" if edge_ground_m > 0 else "the DEM")
    skel = skeletonize(mask)
    n_min = int(np.ceil(min_length_m / cell))
    if n_min > 1:
        skel = remove_small_objects(skel, max_size=n_min - 1, connectivity=2)
    log.info("breaklines: %.2f %% of cells kept above %.3g 1/m (%s curvature, %d x %d window), %d skeleton cells",
             100.0 * mask.mean(), threshold, kind, window, window, int(skel.sum()))
    return skel, k.astype(np.float32)
