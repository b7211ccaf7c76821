"""Compiled kernels of the dense matcher (numba, ``cache=True``).

All kernels work on one tile: a grid of ``H × W`` ground cells with local coordinates
``xs`` (W,) and ``ys`` (H,) of the cell centres.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numba import njit, prange

if TYPE_CHECKING:
    from collections.abc import Sequence


@njit(cache=True)
def _project(R, C, p, X, Y, Z):
    dx = X - C[0]
    dy = Y - C[1]
    dz = Z - C[2]
    xc = R[0, 0] * dx + R[0, 1] * dy + R[0, 2] * dz
    yc = R[1, 0] * dx + R[1, 1] * dy + R[1, 2] * dz
    zc = R[2, 0] * dx + R[2, 1] * dy + R[2, 2] * dz
    if zc <= 1e-6:
        return -1e9, -1e9, zc
    x = xc / zc
    y = yc / zc
    r2 = x * x + y * y
    d = 1.0 + p[3] * r2 + p[4] * r2 * r2
    return p[0] * x * d + p[1], p[0] * y * d + p[2], zc


@njit(cache=True)
def _bilinear(img, u, v):
    h, w = img.shape[0], img.shape[1]
    if not (u >= 0.0 and v >= 0.0 and u <= w - 1.0 and v <= h - 1.0):
        return np.nan
    i0 = min(int(v), h - 2) if h > 1 else 0
    j0 = min(int(u), w - 2) if w > 1 else 0
    a = v - i0
    b = u - j0
    return ((1 - a) * ((1 - b) * img[i0, j0] + b * img[i0, j0 + 1])
            + a * ((1 - b) * img[i0 + 1, j0] + b * img[i0 + 1, j0 + 1]))


@njit(cache=True)
def _sgm_direction(cost, dr, dc, p1, p2, total):
    H, W, K = cost.shape
    L = np.empty((H, W, K), dtype=np.float32)
    r_start, r_end, r_step = (0, H, 1) if dr >= 0 else (H - 1, -1, -1)
    c_start, c_end, c_step = (0, W, 1) if dc >= 0 else (W - 1, -1, -1)
    for r in range(r_start, r_end, r_step):
        for c in range(c_start, c_end, c_step):
            pr = r - dr
            pc = c - dc
            if pr < 0 or pr >= H or pc < 0 or pc >= W:
                for d in range(K):
                    L[r, c, d] = cost[r, c, d]
            else:
                mprev = L[pr, pc, 0]
                for d in range(1, K):
                    if L[pr, pc, d] < mprev:
                        mprev = L[pr, pc, d]
                for d in range(K):
                    best = L[pr, pc, d]
                    if d > 0 and L[pr, pc, d - 1] + p1 < best:
                        best = L[pr, pc, d - 1] + p1
                    if d < K - 1 and L[pr, pc, d + 1] + p1 < best:
                        best = L[pr, pc, d + 1] + p1
                    if mprev + p2 < best:
                        best = mprev + p2
                    L[r, c, d] = cost[r, c, d] + best - mprev
            for d in range(K):
                total[r, c, d] += L[r, c, d]


_DIRS = np.array([[0, 1], [0, -1], [1, 0], [-1, 0], [1, 1], [-1, -1], [1, -1], [-1, 1]], dtype=np.int64)


def sgm_aggregate(cost: np.ndarray, p1: float, p2: float, directions: int) -> np.ndarray:
    """Semi-global aggregation of a cost volume (H, W, K) along 4 or 8 directions.

    Labels are neighbouring steps of the elevation search; a change of one step costs
    ``p1``, a larger jump ``p2``. O(directions · H·W·K) time, O(H·W·K) extra memory.

    Serial on purpose: it is ~2 % of a tile's time, and running the directions (or the
    paths of one direction) in parallel was measured slower on the shared 2-core machine
    (extra buffers and thread barriers; see README, dense matching speed).

    Parameters
    ----------
    cost : ndarray (H, W, K)
        Matching cost per cell and label (converted to contiguous float32).
    p1, p2 : float
        Penalties (cost units) for a one-step change of label and for a larger jump.
    directions : int
        Number of aggregation directions: 4 (rows and columns) or 8 (with the diagonals).

    Returns
    -------
    ndarray (H, W, K) float32
        Aggregated cost: the sum of the path costs over the directions.
    """
    cost = np.ascontiguousarray(cost, dtype=np.float32)
    total = np.zeros_like(cost)
    for dr, dc in _DIRS[: int(directions)]:
        _sgm_direction(cost, int(dr), int(dc), np.float32(p1), np.float32(p2), total)
    return total


@njit(cache=True)
def ncc_cost(score: np.ndarray, nan_cost: float, out: np.ndarray) -> None:
    """SGM cost ``(1 − NCC)/2`` (float32, ``nan_cost`` where NaN) of ``score`` (K, H, W),
    written transposed into ``out`` (H, W, K). Serial: a parallel region costs more than
    this pass on the shared 2-core machine. O(K·H·W).

    Parameters
    ----------
    score : ndarray (K, H, W) float32
        Multi-view NCC per label and cell (NaN = not judged).
    nan_cost : float
        Cost written where the NCC is NaN.
    out : ndarray (H, W, K) float32
        Receives the cost; written in place.
    """
    K, H, W = score.shape
    one = np.float32(1.0)
    half = np.float32(0.5)
    nc = np.float32(nan_cost)
    for i in range(H):
        for k in range(K):
            for j in range(W):
                s = score[k, i, j]
                out[i, j, k] = (one - s) * half if np.isfinite(s) else nc


@njit(cache=True)
def sgm_winner(agg: np.ndarray, d_out: np.ndarray, off_out: np.ndarray) -> None:
    """Label of least aggregated cost ``agg`` (H, W, K) per cell (first on ties, as
    ``np.argmin``) into ``d_out`` and the sub-step offset in [−0.5, 0.5] of a parabola
    through the costs around it (0 at the first and last label) into ``off_out``, in the
    float32 arithmetic of the former numpy code. Serial (as :func:`ncc_cost`). O(H·W·K).

    Parameters
    ----------
    agg : ndarray (H, W, K) float32
        Aggregated cost per cell and label (:func:`sgm_aggregate`).
    d_out : ndarray (H, W) int64
        Receives the winning label; written in place.
    off_out : ndarray (H, W) float32
        Receives the sub-step offset (labels); written in place.
    """
    H, W, K = agg.shape
    two = np.float32(2.0)
    half = np.float32(0.5)
    eps = np.float32(1e-12)
    for i in range(H):
        for j in range(W):
            a = agg[i, j]
            best = a[0]
            d = 0
            for k in range(1, K):
                if a[k] < best:
                    best = a[k]
                    d = k
            d_out[i, j] = d
            off = np.float32(0.0)
            if K >= 3 and d >= 1 and d <= K - 2:
                cm = a[d - 1]
                c0 = a[d]
                cp = a[d + 1]
                den = cm - two * c0 + cp
                if den > eps:
                    off = half * (cm - cp) / den
                    if off < -half:
                        off = -half
                    elif off > half:
                        off = half
            off_out[i, j] = off


@njit(cache=True)
def _height_nearest(dsm, x0, y0, cell, x, y):
    j = int(np.floor((x - x0) / cell))
    i = int(np.floor((y0 - y) / cell))
    if i < 0 or j < 0 or i >= dsm.shape[0] or j >= dsm.shape[1]:
        return np.nan
    return dsm[i, j]


@njit(cache=True, parallel=True)
def occlusion_mask(dsm: np.ndarray, x0: float, y0: float, cell: float, zmax: float, xs: np.ndarray, ys: np.ndarray,
                   Z: np.ndarray, C: np.ndarray, step: float, tolerance: float, out: np.ndarray) -> None:
    """True where the line of sight from ground point ``(xs[j], ys[i], Z[i, j])`` to the
    camera centre ``C`` passes below the surface ``dsm`` (grid with top-left corner
    ``(x0, y0)`` and cell ``cell``, local coordinates) by more than ``tolerance``.

    The ray is marched in horizontal steps of ``step`` until it rises above ``zmax``.
    O(H·W·L/step) with L the horizontal run of the ray below ``zmax``.

    Parameters
    ----------
    dsm : ndarray (h, w)
        Surface elevations (local, m; NaN = no value, never blocks).
    x0, y0 : float
        Top-left corner of ``dsm`` (local, m).
    cell : float
        Cell size of ``dsm`` (m); each ray sample takes the height of the cell that contains it.
    zmax : float
        Elevation (local, m) above which nothing blocks the ray (the top of ``dsm``): the march stops there.
    xs, ys : ndarray (W,), (H,)
        Local coordinates of the ground cell centres (m).
    Z : ndarray (H, W)
        Ground elevation of each cell (local, m); NaN cells are not blocked.
    C : ndarray (3,)
        Camera centre (local, m).
    step : float
        Horizontal step of the march (m).
    tolerance : float
        Height (m) by which the surface must rise above the ray to block it.
    out : ndarray (H, W) bool
        Receives the mask; written in place. Also True where the camera is not above the ground point.
    """
    for i in prange(Z.shape[0]):
        for j in range(Z.shape[1]):
            z = Z[i, j]
            out[i, j] = False
            if not np.isfinite(z):
                continue
            dx = C[0] - xs[j]
            dy = C[1] - ys[i]
            dz = C[2] - z
            hd = np.sqrt(dx * dx + dy * dy)
            if dz <= 0.0:
                out[i, j] = True
                continue
            if hd < 1e-9:
                continue
            slope = dz / hd
            t = step
            while True:
                zr = z + slope * t
                if zr > zmax or t > hd:
                    break
                zs = _height_nearest(dsm, x0, y0, cell, xs[j] + dx * t / hd, ys[i] + dy * t / hd)
                if np.isfinite(zs) and zs > zr + tolerance:
                    out[i, j] = True
                    break
                t += step


@njit(cache=True, parallel=True)
def openness_kernel(z: np.ndarray, cell: float, radius: int, out: np.ndarray) -> None:
    """Positive openness (degrees): mean over 8 directions of 90° minus the highest
    elevation angle within ``radius`` cells. NaN cells are skipped. O(H·W·8·radius).

    Parameters
    ----------
    z : ndarray (H, W) float64
        Elevations (m, NaN = no value).
    cell : float
        Cell size (m).
    radius : int
        Search radius along each direction (cells).
    out : ndarray (H, W) float64
        Receives the openness (degrees); written in place. NaN where ``z`` is NaN or no direction has a valid cell.
    """
    H, W = z.shape
    di = (0, 1, 1, 1, 0, -1, -1, -1)
    dj = (1, 1, 0, -1, -1, -1, 0, 1)
    for i in prange(H):
        for j in range(W):
            z0 = z[i, j]
            if not np.isfinite(z0):
                out[i, j] = np.nan
                continue
            tot = 0.0
            nd = 0
            for k in range(8):
                best = -1e30
                step_len = cell * (1.4142135623730951 if di[k] != 0 and dj[k] != 0 else 1.0)
                for r in range(1, radius + 1):
                    a = i + di[k] * r
                    b = j + dj[k] * r
                    if a < 0 or b < 0 or a >= H or b >= W:
                        break
                    zz = z[a, b]
                    if not np.isfinite(zz):
                        continue
                    g = (zz - z0) / (r * step_len)
                    if g > best:
                        best = g
                if best > -1e29:
                    tot += 90.0 - np.degrees(np.arctan(best))
                    nd += 1
            out[i, j] = tot / nd if nd > 0 else np.nan


@njit(cache=True, parallel=True)
def sample_stack(imgs: Sequence[np.ndarray], Rs: np.ndarray, Cs: np.ndarray, Ps: np.ndarray, levels: np.ndarray,
                 xs: np.ndarray, ys: np.ndarray, base: np.ndarray, dz: float, out: np.ndarray) -> None:
    """Resample every view at every candidate surface ``base + k·dz`` (k = 0 … K−1).

    ``imgs`` is a typed list of (h, w) float32 pyramid levels, one per view, with
    ``levels`` their pyramid levels; ``out`` (K, V, H, W) gets NaN outside an image or
    behind its camera. One parallel region for the whole level keeps thread
    synchronisation negligible. O(K·V·H·W).

    The rotation's horizontal part ``R[:, 0]·(X − Cx) + R[:, 1]·(Y − Cy)`` does not depend
    on the candidate elevation: it is computed once per view and cell and the candidates
    add only ``R[:, 2]·(Z − Cz)``, in the same order of operations as :func:`_project`, so
    the samples are bit for bit those of projecting every candidate in full.

    Parameters
    ----------
    imgs : typed list of ndarray (h, w) float32
        Grey pyramid level of each view.
    Rs : ndarray (V, 3, 3) float64
        Rotations world → camera.
    Cs : ndarray (V, 3) float64
        Projection centres (local, m).
    Ps : ndarray (V, 5) float64
        Intrinsics ``(f, cx, cy, k1, k2)`` in level-0 pixels.
    levels : ndarray (V,) int64
        Pyramid level of each image in ``imgs``.
    xs, ys : ndarray (W,), (H,)
        Local coordinates of the cell centres (m).
    base : ndarray (H, W) float64
        Lowest candidate elevation of each cell (local, m); a NaN cell gets NaN samples.
    dz : float
        Step between candidates (m).
    out : ndarray (K, V, H, W) float32
        Receives the samples; written in place. K is the number of candidates.
    """
    K, V, H, W = out.shape
    for i in prange(H):
        h0 = np.empty(W, dtype=np.float64)
        h1 = np.empty(W, dtype=np.float64)
        h2 = np.empty(W, dtype=np.float64)
        uu = np.empty(W, dtype=np.float64)
        ww = np.empty(W, dtype=np.float64)
        for v in range(V):
            img = imgs[v]
            sc = 1.0 / (2.0 ** levels[v])
            R = Rs[v]
            C = Cs[v]
            p = Ps[v]
            dy = ys[i] - C[1]
            for j in range(W):
                dx = xs[j] - C[0]
                h0[j] = R[0, 0] * dx + R[0, 1] * dy
                h1[j] = R[1, 0] * dx + R[1, 1] * dy
                h2[j] = R[2, 0] * dx + R[2, 1] * dy
            r02, r12, r22, cz = R[0, 2], R[1, 2], R[2, 2], C[2]
            f, cx, cy, k1, k2 = p[0], p[1], p[2], p[3], p[4]
            bi = base[i]
            # k outside j: the writes run along contiguous rows of ``out``
            for k in range(K):
                # projection of the whole row first (no branches: SIMD), then the samples
                for j in range(W):
                    z = bi[j] + k * dz
                    dzc = z - cz
                    zc = h2[j] + r22 * dzc
                    x = (h0[j] + r02 * dzc) / zc
                    y = (h1[j] + r12 * dzc) / zc
                    r2 = x * x + y * y
                    d = 1.0 + k1 * r2 + k2 * r2 * r2
                    u = f * x * d + cx
                    w = f * y * d + cy
                    # behind the camera (or at its centre), or no candidate: outside any image
                    bad = not (zc > 1e-6) or not np.isfinite(z)
                    uu[j] = -1e9 if bad else (u + 0.5) * sc - 0.5
                    ww[j] = -1e9 if bad else (w + 0.5) * sc - 0.5
                ok = out[k, v, i]
                for j in range(W):
                    ok[j] = _bilinear(img, uu[j], ww[j])


@njit(cache=True, parallel=True)
def multiview_ncc_stack(stack: np.ndarray, half: int, min_std: np.ndarray, score: np.ndarray,
                        nviews: np.ndarray) -> None:
    """Multi-image normalised cross-correlation of ground windows for every candidate.

    ``stack`` (K, V, H, W) holds the V images resampled on the ground grid at K candidate
    surfaces. For each cell and candidate, every view whose ``(2·half+1)²`` window is
    complete and has a standard deviation ≥ ``min_std[v]`` (DN, one threshold per view:
    ``min_std`` is a (V,) array) is normalised to zero mean and unit
    norm (vector ``a_v``); the score is the mean pairwise NCC, obtained without forming
    pairs as ``(‖Σ a_v‖² − n) / (n (n − 1))``. ``score`` (K, H, W) gets NaN where fewer
    than two views remain, ``nviews`` the count of usable views.
    O(K·H·W·V·(2·half+1)²).

    Layout: one output row per parallel iteration (``prange`` over rows: both cores); the
    window sums ``Σ a_v`` of a whole row are accumulated as a ((2·half+1)², W) array,
    window offset outermost and the cells of the row innermost, over slices starting at
    index 0 (no negative-index checks), so the innermost loops run along contiguous image
    rows and compile to SIMD instructions (3× faster than the former per-cell loop on one
    thread). Each cell's sums add the views in the same order and float64 arithmetic as a
    per-cell loop would, so the scores are bit for bit those of the former kernel
    (benchmarks/dense_kernels_speed.py; tests/dense/test_kernels_ncc.py checks them
    against the definition).

    Parameters
    ----------
    stack : ndarray (K, V, H, W) float32
        The resampled images (:func:`sample_stack`; NaN = no sample).
    half : int
        Window half-size (cells).
    min_std : ndarray (V,) float64
        Lowest window standard deviation (DN) of each view.
    score : ndarray (K, H, W) float32
        Receives the mean pairwise NCC; written in place. Also NaN within ``half`` cells of the tile's edges.
    nviews : ndarray (K, H, W) int16
        Receives the number of usable views; written in place (0 within ``half`` cells of the edges).
    """
    K, V, H, W = stack.shape
    m = 2 * half + 1
    n = m * m
    Wn = W - 2 * half  # cells of a row with a complete window: t = j − half
    f0 = np.float32(0.0)
    for i in prange(H):
        col1 = np.empty(W, dtype=np.float64)
        col2 = np.empty(W, dtype=np.float64)
        colc = np.empty(W, dtype=np.int64)
        s1w = np.empty(max(Wn, 1), dtype=np.float64)
        s2w = np.empty(max(Wn, 1), dtype=np.float64)
        cw = np.empty(max(Wn, 1), dtype=np.int64)
        mean = np.empty((V, max(Wn, 1)), dtype=np.float64)
        inv = np.empty((V, max(Wn, 1)), dtype=np.float64)
        acc = np.empty((n, max(Wn, 1)), dtype=np.float64)
        tot = np.empty(max(Wn, 1), dtype=np.float64)
        nvr = np.empty(max(Wn, 1), dtype=np.int64)
        for k in range(K):
            for j in range(W):
                score[k, i, j] = np.nan
                nviews[k, i, j] = 0
            if i < half or i >= H - half or Wn < 1:
                continue
            acc[:, :] = 0.0
            nvr[:] = 0
            for v in range(V):
                # window mean and 1/norm: column sums (rows outer, contiguous), then the
                # running sums of the former kernel (serial), then mean and norm (SIMD)
                col1[:] = 0.0
                col2[:] = 0.0
                colc[:] = 0
                for a in range(i - half, i + half + 1):
                    row = stack[k, v, a]
                    for j in range(W):
                        x = row[j]
                        fin = np.isfinite(x)
                        col1[j] += x if fin else f0
                        col2[j] += x * x if fin else f0
                        colc[j] += 1 if fin else 0
                s1 = 0.0
                s2 = 0.0
                c = 0
                for j in range(W):
                    s1 += col1[j]
                    s2 += col2[j]
                    c += colc[j]
                    if j >= m:
                        s1 -= col1[j - m]
                        s2 -= col2[j - m]
                        c -= colc[j - m]
                    if j >= m - 1:
                        s1w[j - m + 1] = s1
                        s2w[j - m + 1] = s2
                        cw[j - m + 1] = c
                thr = n * min_std[v] * min_std[v]
                mv = mean[v]
                iv = inv[v]
                for t in range(Wn):
                    mu = s1w[t] / n
                    ss = s2w[t] - n * mu * mu
                    mv[t] = mu
                    iv[t] = 1.0 / np.sqrt(ss) if (cw[t] == n and ss >= thr and ss > 0.0) else 0.0
                t_lo = Wn
                t_hi = -1
                for t in range(Wn):
                    if iv[t] != 0.0:
                        if t < t_lo:
                            t_lo = t
                        t_hi = t
                if t_hi < 0:
                    continue  # no usable window of this view on this row
                nt = t_hi + 1 - t_lo
                ivs = iv[t_lo:t_hi + 1]
                mvs = mv[t_lo:t_hi + 1]
                nvs = nvr[t_lo:t_hi + 1]
                for t in range(nt):
                    nvs[t] += 1 if ivs[t] != 0.0 else 0
                # Σ a_v of every window offset q for the whole row: contiguous slices, SIMD
                q = 0
                for a in range(i - half, i + half + 1):
                    row = stack[k, v, a]
                    for b in range(m):
                        accq = acc[q, t_lo:t_hi + 1]
                        ro = row[t_lo + b:t_lo + b + nt]
                        for t in range(nt):
                            w = ivs[t]
                            # a view without a usable window adds nothing (its pixels may be NaN)
                            accq[t] += (ro[t] - mvs[t]) * w if w != 0.0 else 0.0
                        q += 1
            tot[:] = 0.0
            for q in range(n):
                accq = acc[q]
                for t in range(Wn):
                    tot[t] += accq[t] * accq[t]
            for t in range(Wn):
                nv = nvr[t]
                nviews[k, i, t + half] = nv
                if nv >= 2:
                    score[k, i, t + half] = (tot[t] - nv) / (nv * (nv - 1.0))


@njit(cache=True, parallel=True)
def best_view_ortho(imgs: Sequence[np.ndarray], Rs: np.ndarray, Cs: np.ndarray, Ps: np.ndarray, levels: np.ndarray,
                    widths: np.ndarray, heights: np.ndarray, xs: np.ndarray, ys: np.ndarray, Z: np.ndarray,
                    dsm: np.ndarray, x0: float, y0: float, cell: float, zmax: float, step: float,
                    tolerance: float, out: np.ndarray, source: np.ndarray) -> None:
    """True-orthophoto colours: for each ground point take the most nadir image that sees it.

    For each cell the views are tried from the smallest off-nadir angle of the line of
    sight up; the first one whose frame contains the point and whose line of sight is not
    blocked by ``dsm`` (as :func:`occlusion_mask`) gives the colour (bilinear, pyramid
    ``levels``). ``out`` (B, H, W) gets NaN and ``source`` −1 where no view qualifies.
    Only the winning view's ray is usually marched: O(H·W·(V log V + L/step)).

    Parameters
    ----------
    imgs : typed list of ndarray (h, w, B) float32
        Colour pyramid level of each view.
    Rs : ndarray (V, 3, 3) float64
        Rotations world → camera.
    Cs : ndarray (V, 3) float64
        Projection centres (local, m).
    Ps : ndarray (V, 5) float64
        Intrinsics ``(f, cx, cy, k1, k2)`` in level-0 pixels.
    levels : ndarray (V,) int64
        Pyramid level of each image in ``imgs``.
    widths, heights : ndarray (V,) int64
        Level-0 image sizes (px).
    xs, ys : ndarray (W,), (H,)
        Local coordinates of the orthophoto cell centres (m).
    Z : ndarray (H, W) float64
        Surface elevation of each orthophoto cell (local, m); NaN cells get no colour.
    dsm : ndarray (h, w) float64
        Surface elevations for the occlusion test (local, m; NaN = no value, never blocks).
    x0, y0 : float
        Top-left corner of ``dsm`` (local, m).
    cell : float
        Cell size of ``dsm`` (m).
    zmax : float
        Elevation (local, m) above which nothing blocks a ray (the top of ``dsm``): the march stops there.
    step : float
        Horizontal step of the ray march (m).
    tolerance : float
        Height (m) by which the surface must rise above a ray to block it.
    out : ndarray (B, H, W) float32
        Receives the colours (0–255 as the images); written in place.
    source : ndarray (H, W) int64
        Receives the index in ``imgs`` of the chosen view; written in place.
    """
    V = len(imgs)
    nb = out.shape[0]
    for i in prange(Z.shape[0]):
        cosang = np.empty(V, dtype=np.float64)
        for j in range(Z.shape[1]):
            source[i, j] = -1
            for b in range(nb):
                out[b, i, j] = np.nan
            z = Z[i, j]
            if not np.isfinite(z):
                continue
            for v in range(V):
                dx = Cs[v, 0] - xs[j]
                dy = Cs[v, 1] - ys[i]
                dz = Cs[v, 2] - z
                cosang[v] = dz / np.sqrt(dx * dx + dy * dy + dz * dz)
            order = np.argsort(-cosang)
            for t in range(V):
                v = order[t]
                if cosang[v] <= 0.0:
                    break
                u, w, d = _project(Rs[v], Cs[v], Ps[v], xs[j], ys[i], z)
                if d <= 0.0 or u < 0.0 or w < 0.0 or u > widths[v] - 1.0 or w > heights[v] - 1.0:
                    continue
                # occlusion: march towards the camera until the ray is above zmax
                dx = Cs[v, 0] - xs[j]
                dy = Cs[v, 1] - ys[i]
                hd = np.sqrt(dx * dx + dy * dy)
                blocked = False
                if hd > 1e-9:
                    slope = (Cs[v, 2] - z) / hd
                    s = step
                    while s <= hd:
                        zr = z + slope * s
                        if zr > zmax:
                            break
                        zs = _height_nearest(dsm, x0, y0, cell, xs[j] + dx * s / hd, ys[i] + dy * s / hd)
                        if np.isfinite(zs) and zs > zr + tolerance:
                            blocked = True
                            break
                        s += step
                if blocked:
                    continue
                sc = 1.0 / (2.0 ** levels[v])
                img = imgs[v]
                uu = (u + 0.5) * sc - 0.5
                ww = (w + 0.5) * sc - 0.5
                for b in range(nb):
                    out[b, i, j] = _bilinear(img[:, :, b], uu, ww)
                source[i, j] = v
                break
