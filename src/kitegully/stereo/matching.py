"""Coarse-to-fine epipolar matching, triangulation and gridding (Moritani et al. 2010, sect. 2).

Matching works on a rectified pair, so a left pixel ``(x, y)`` matches the right pixel
``(x − d, y)`` with d the disparity. Both images are reduced to Gaussian pyramids whose
levels are filtered with a Laplacian of Gaussian (band-pass: it removes the brightness
differences between two cameras). At the coarsest level every pixel searches the whole
disparity range given by the object-distance range; each finer level doubles the
disparity and searches ±``search_px`` around it. The cost is the normalised cross
correlation (NCC) over a square window, computed for all pixels at once with box filters
on the right image warped by the current disparity (``cv2.remap``), so a level costs
O(pixels · (2·search_px + 1)). The peak is refined with a parabola through the NCC at
k − 1, k, k + 1; the finest level is iterated so the last parabola is centred on the peak
(small pixel-locking bias).

Triangulation uses the rectification's Q matrix (``(x, y, d, 1) → (X, Y, Z, W)``), or
``cv2.triangulatePoints`` for single measured points, then the left camera's pose to world.
Gridding averages the points per DEM cell.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from kitegully import InputError
from kitegully.io.raster import GridSpec, Raster
from kitegully.stereo.rectify import Rectification
from kitegully.twin.camera import Pose

log = logging.getLogger(__name__)


def _cv2():
    import cv2

    return cv2


def band_filter(image: np.ndarray, kind: str = "log", sigma_px: float = 1.0) -> np.ndarray:
    """Filter one pyramid level: ``"log"`` (−Laplacian of Gaussian), ``"gauss"`` or ``"none"``; NaNs stay NaN.

    Parameters
    ----------
    image : ndarray (H, W)
        One pyramid level (NaN = no data).
    kind : str
        ``"log"``, ``"gauss"`` or ``"none"``.
    sigma_px : float
        Gaussian σ of the filter (px).

    Returns
    -------
    ndarray (H, W) float32
        The filtered level; NaN within ⌈3·sigma_px⌉ px (square neighbourhood) of any NaN of ``image``.
    """
    cv2 = _cv2()
    img = np.asarray(image, np.float32)
    bad = ~np.isfinite(img)
    src = np.where(bad, np.nanmean(img) if (~bad).any() else 0.0, img).astype(np.float32)
    if kind == "none":
        out = src
    elif kind == "gauss":
        out = cv2.GaussianBlur(src, (0, 0), sigma_px)
    elif kind == "log":
        out = -cv2.Laplacian(cv2.GaussianBlur(src, (0, 0), sigma_px), cv2.CV_32F, ksize=3)
    else:
        raise InputError(f"matching: filter {kind!r} is not one of 'log', 'gauss', 'none'")
    if bad.any():
        k = int(2 * np.ceil(3 * sigma_px) + 1)
        out[cv2.dilate(bad.astype(np.uint8), np.ones((k, k), np.uint8)) > 0] = np.nan
    return out


def _pyramid(image: np.ndarray, levels: int) -> list[np.ndarray]:
    cv2 = _cv2()
    out = [np.asarray(image, np.float32)]
    for _ in range(levels):
        a = out[-1]
        bad = ~np.isfinite(a)
        down = cv2.pyrDown(np.where(bad, 0, a).astype(np.float32))
        if bad.any():
            badd = cv2.pyrDown(bad.astype(np.float32)) > 1e-3
            down[badd] = np.nan
        out.append(down)
    return out


def _ncc(L: np.ndarray, S: np.ndarray, win: int) -> np.ndarray:
    """Windowed NCC of two equally shaped images; NaN where either window has a NaN or no texture."""
    cv2 = _cv2()
    bad = ~(np.isfinite(L) & np.isfinite(S))
    L0, S0 = np.where(bad, 0, L).astype(np.float32), np.where(bad, 0, S).astype(np.float32)
    box = lambda a: cv2.boxFilter(a, cv2.CV_32F, (win, win), normalize=True, borderType=cv2.BORDER_REFLECT)  # noqa: E731
    mL, mS = box(L0), box(S0)
    vL = box(L0 * L0) - mL * mL
    vS = box(S0 * S0) - mS * mS
    c = box(L0 * S0) - mL * mS
    with np.errstate(invalid="ignore", divide="ignore"):
        r = c / np.sqrt(np.maximum(vL, 0) * np.maximum(vS, 0))
    badw = box(bad.astype(np.float32)) > 1e-6
    r[badw | (vL <= 1e-6) | (vS <= 1e-6)] = np.nan
    return r


def _fill(d: np.ndarray, fallback: float) -> np.ndarray:
    """Replace NaNs by the mean of valid neighbours (growing windows), else ``fallback``."""
    cv2 = _cv2()
    out = d.copy()
    for k in (5, 15, 45):
        bad = ~np.isfinite(out)
        if not bad.any():
            break
        ok = (~bad).astype(np.float32)
        s = cv2.boxFilter(np.where(bad, 0, out).astype(np.float32), -1, (k, k), normalize=False)
        n = cv2.boxFilter(ok, -1, (k, k), normalize=False)
        with np.errstate(invalid="ignore", divide="ignore"):
            out[bad] = (s / n)[bad]
    out[~np.isfinite(out)] = fallback
    return out


@dataclass(frozen=True)
class MatchParams:
    """Parameters of the coarse-to-fine matcher.

    Attributes
    ----------
    levels : int
        Pyramid levels above full resolution. [I] Enough that the disparity range at the
        coarsest level spans only a few pixels: ``2^levels ≳ (d_max − d_min)/8``.
    window_px : int
        NCC window side (odd, px) at every level. [I] ~ a few texture grains: 11 px.
    search_px : int
        Residual search ±px at the finer levels (≥ 1; 2 tolerates a 1-px coarse error).
    refine_iterations : int
        Extra full-resolution iterations with ±1 px (centres the sub-pixel parabola).
    filter : str
        ``"log"`` (paper: Laplacian of Gaussian), ``"gauss"`` or ``"none"``.
    sigma_px : float
        Gaussian σ of the level filter (px).
    min_ncc : float
        Matches with a lower final NCC are dropped.
    """

    levels: int = 4
    window_px: int = 11
    search_px: int = 2
    refine_iterations: int = 2
    filter: str = "log"
    sigma_px: float = 1.0
    min_ncc: float = 0.6

    def __post_init__(self) -> None:
        if self.window_px < 3 or self.window_px % 2 == 0:
            raise InputError(f"matching: window_px = {self.window_px} must be an odd number ≥ 3")
        if self.levels < 0 or self.search_px < 1:
            raise InputError(f"matching: levels = {self.levels} must be ≥ 0 and search_px = {self.search_px} ≥ 1")


@dataclass(frozen=True)
class Disparity:
    """Dense disparity of the left rectified image (px, NaN = no match) and its NCC."""

    d: np.ndarray
    score: np.ndarray

    @property
    def valid(self) -> np.ndarray:
        """Boolean mask of the matched pixels (finite disparity)."""
        return np.isfinite(self.d)


def _level(Ll, Rl, d_cur, ox, shifts, win, cv2):
    """NCC of ``Ll`` against the right level warped by ``d_cur + k`` for each k in ``shifts``."""
    h, w = Ll.shape
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    scores = np.empty((len(shifts), h, w), np.float32)
    for i, k in enumerate(shifts):
        mx = (xx + ox - d_cur - k).astype(np.float32)
        S = cv2.remap(Rl, mx, yy, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=np.nan)
        scores[i] = _ncc(Ll, S, win)
    return scores


def _peak(scores: np.ndarray, shifts: np.ndarray):
    filled = np.where(np.isfinite(scores), scores, -2.0)
    i = np.argmax(filled, axis=0)
    best = np.take_along_axis(filled, i[None], 0)[0]
    n = len(shifts)
    im, ip = np.clip(i - 1, 0, n - 1), np.clip(i + 1, 0, n - 1)
    sm = np.take_along_axis(filled, im[None], 0)[0]
    sp = np.take_along_axis(filled, ip[None], 0)[0]
    den = sm - 2 * best + sp
    with np.errstate(invalid="ignore", divide="ignore"):
        delta = np.where(den < 0, 0.5 * (sm - sp) / den, 0.0)
    interior = (i > 0) & (i < n - 1) & (sm > -2) & (sp > -2)
    delta = np.clip(delta, -0.5, 0.5)
    k = shifts[i] + delta
    ok = interior & (best > -2)
    return np.where(ok, k, np.nan), np.where(best > -2, best, np.nan)


def match_epipolar(left: np.ndarray, right: np.ndarray, d_range: tuple[float, float],
                   params: MatchParams = MatchParams(), roi: tuple[int, int, int, int] | None = None) -> Disparity:
    """Dense coarse-to-fine NCC matching of a rectified pair along its rows.

    Parameters
    ----------
    left, right : ndarray (H, W)
        Rectified grey images (NaN = no data), same number of rows.
    d_range : (float, float)
        Disparity range to search at the coarsest level (px), from the object-distance range
        (:meth:`Rectification.disparity_for_depth`).
    params : MatchParams
    roi : (x0, y0, x1, y1), optional
        Part of the left image to match (px, end exclusive); default the whole image.

    Returns
    -------
    Disparity
        Arrays the size of ``left``; NaN outside ``roi`` and where matching failed.

    Notes
    -----
    Cost: O(roi pixels · (2·search_px + 1) · (1 + refine_iterations + 1/3)) box-filter
    passes; a 600 × 1000 px box takes a few seconds on one core.
    """
    cv2 = _cv2()
    left, right = np.asarray(left, np.float32), np.asarray(right, np.float32)
    if left.ndim != 2 or right.ndim != 2 or left.shape[0] != right.shape[0]:
        raise InputError(f"matching: the rectified images must be 2-D with the same number of rows ({left.shape} vs {right.shape})")
    dmin, dmax = sorted(float(v) for v in d_range)
    H, W = left.shape
    s = 2 ** params.levels
    x0, y0, x1, y1 = roi if roi is not None else (0, 0, W, H)
    x0, y0 = (max(0, x0) // s) * s, (max(0, y0) // s) * s
    x1, y1 = min(W, x1), min(H, y1)
    if x1 - x0 < params.window_px * s or y1 - y0 < params.window_px * s:
        raise InputError(f"matching: region {roi} is too small for {params.levels} pyramid levels of {params.window_px}-px windows")
    # overlap: some right column x − d must exist for some left column and disparity
    if x0 - dmax > right.shape[1] - 1 or x1 - 1 - dmin < 0:
        raise InputError(f"matching: the pair has no overlap: left columns {x0}–{x1 - 1} minus disparities {dmin:g}–{dmax:g} px "
                         f"fall outside the right image (width {right.shape[1]})")
    Lc, Rc = left[y0:y1, x0:x1], right[y0:y1, :]
    Lp, Rp = _pyramid(Lc, params.levels), _pyramid(Rc, params.levels)
    d_cur = None
    score = None
    for lev in range(params.levels, -1, -1):
        f = 2.0 ** lev
        Ll = band_filter(Lp[lev], params.filter, params.sigma_px)
        Rl = band_filter(Rp[lev], params.filter, params.sigma_px)
        ox = x0 / f
        if d_cur is None:
            centre = 0.5 * (dmin + dmax) / f
            half = int(np.ceil(0.5 * (dmax - dmin) / f)) + 1
            d_cur = np.full(Ll.shape, centre, np.float32)
            shifts = np.arange(-half, half + 1, dtype=np.float32)
        else:
            d_cur = 2.0 * cv2.resize(d_cur, (Ll.shape[1], Ll.shape[0]), interpolation=cv2.INTER_LINEAR)
            shifts = np.arange(-params.search_px, params.search_px + 1, dtype=np.float32)
        iters = 1 + (params.refine_iterations if lev == 0 else 0)
        for it in range(iters):
            sh = shifts if it == 0 else np.array([-1.0, 0.0, 1.0], np.float32)
            if it > 0:
                # warp with a field smoothed over the window: a per-pixel noisy warp would jitter the window content
                d_cur = cv2.blur(d_cur, (params.window_px, params.window_px), borderType=cv2.BORDER_REPLICATE)
            k, score = _peak(_level(Ll, Rl, d_cur, ox, sh, params.window_px, cv2), sh)
            d_new = d_cur + k
            med = cv2.medianBlur(_fill(d_new, float(np.nanmedian(d_new)) if np.isfinite(d_new).any() else 0.0).astype(np.float32), 5)
            if lev > 0 or it < iters - 1:
                # propagate a robust field: outliers and holes take the local median
                bad = ~np.isfinite(d_new) | (np.abs(d_new - med) > 1.0) | ~(score >= params.min_ncc * 0.5)
                d_cur = np.where(bad, med, d_new).astype(np.float32)
            else:
                d_cur = np.where(np.abs(d_new - med) > 1.0, np.nan, d_new).astype(np.float32)
        log.debug("matching level %d: %.0f%% matched", lev, 100 * np.mean(np.isfinite(k)))
    d_cur = np.where(score >= params.min_ncc, d_cur, np.nan)
    if not np.isfinite(d_cur).any():
        raise InputError("matching: no pixel of the pair matched (NCC below min_ncc everywhere): the images do not overlap or have no texture")
    D = np.full(left.shape, np.nan, np.float32)
    Sc = np.full(left.shape, np.nan, np.float32)
    D[y0:y1, x0:x1] = d_cur
    Sc[y0:y1, x0:x1] = score
    log.info("matched %d of %d pixels (%.1f %%)", int(np.isfinite(d_cur).sum()), d_cur.size, 100 * np.isfinite(d_cur).mean())
    return Disparity(D, Sc)


def rectified_to_world(X_rect: np.ndarray, rect: Rectification, pose_left: Pose) -> np.ndarray:
    """Points in the left rectified frame (N × 3) to world: ``X_w = R_lᵀ R1ᵀ X_rect + C_l``.

    Parameters
    ----------
    X_rect : ndarray (N, 3)
        Points in the left rectified frame (m).
    rect : Rectification
        The pair's rectification; gives ``R1``.
    pose_left : Pose
        World pose of the left camera.

    Returns
    -------
    ndarray (N, 3)
        World points (m).
    """
    X = np.ascontiguousarray(X_rect, dtype=float)  # a strided slice would make matmul fall off BLAS (seconds per Mpt)
    return (X @ rect.R1) @ pose_left.R + pose_left.C


def disparity_to_points(disp: Disparity, rect: Rectification, pose_left: Pose, step: int = 1) -> np.ndarray:
    """World points (N × 3, m) of every ``step``-th valid disparity pixel via the Q matrix.

    Cost: O(valid pixels).

    Parameters
    ----------
    disp : Disparity
        Dense disparity of the left rectified image (px, NaN = no match).
    rect : Rectification
        The pair's rectification; gives ``Q`` and ``R1``.
    pose_left : Pose
        World pose of the left camera.
    step : int
        Take every ``step``-th row and column.

    Returns
    -------
    ndarray (N, 3)
        World points (m), one per valid sampled pixel, in row-major order.
    """
    d = disp.d[::step, ::step]
    yy, xx = np.mgrid[0:disp.d.shape[0]:step, 0:disp.d.shape[1]:step]
    ok = np.isfinite(d)
    h = np.column_stack([xx[ok], yy[ok], d[ok], np.ones(ok.sum())]).astype(float) @ rect.Q.T
    X = h[:, :3] / h[:, 3:4]
    return rectified_to_world(X, rect, pose_left)


def triangulate_points(rect: Rectification, uv_left_rect: np.ndarray, uv_right_rect: np.ndarray, pose_left: Pose) -> np.ndarray:
    """World points (N × 3) of matched rectified pixel pairs (point measurement), ``cv2.triangulatePoints``.

    Parameters
    ----------
    rect : Rectification
        The pair's rectification; gives ``P1``, ``P2`` and ``R1``.
    uv_left_rect, uv_right_rect : ndarray (N, 2)
        Matched pixel positions in the left and right rectified images (px).
    pose_left : Pose
        World pose of the left camera.

    Returns
    -------
    ndarray (N, 3)
        World points (m).
    """
    cv2 = _cv2()
    a = np.asarray(uv_left_rect, float).T
    b = np.asarray(uv_right_rect, float).T
    Xh = cv2.triangulatePoints(rect.P1, rect.P2, a, b)
    return rectified_to_world((Xh[:3] / Xh[3]).T, rect, pose_left)


def grid_dem(points: np.ndarray, grid: GridSpec, min_count: int = 1) -> Raster:
    """Mean elevation of the points in each cell of ``grid`` (float32, NaN where fewer than ``min_count``).

    Cost: O(points + cells).

    Parameters
    ----------
    points : ndarray (N, 3)
        World points x, y, z (m); points outside ``grid`` or with a non-finite z are ignored.
    grid : GridSpec
        The DEM grid.
    min_count : int
        Fewest points a cell needs for a value (below 1 counts as 1).

    Returns
    -------
    Raster
        Mean elevation per cell (m, float32) on ``grid``.
    """
    P = np.asarray(points, float)
    if P.ndim != 2 or P.shape[1] != 3:
        raise InputError(f"grid_dem: points must be an N × 3 array, got shape {P.shape}")
    row, col = grid.index(P[:, 0], P[:, 1])
    ok = grid.contains(P[:, 0], P[:, 1]) & np.isfinite(P[:, 2])
    idx = row[ok] * grid.width + col[ok]
    n = np.bincount(idx, minlength=grid.width * grid.height)
    s = np.bincount(idx, weights=P[ok, 2], minlength=grid.width * grid.height)
    with np.errstate(invalid="ignore", divide="ignore"):
        z = np.where(n >= max(min_count, 1), s / n, np.nan).reshape(grid.height, grid.width).astype(np.float32)
    return Raster(z, grid)
