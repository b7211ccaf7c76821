"""The folding rule's two 1 m legs measured in the photogrammetric model (001 sect. 2.2, scale check).

The rule (yellow, 2 cm wide, black decimetre marks) is found in the orthophoto by its
known colour.  A 2 cm strip on 2 cm cells is mixed with the grass beside it, so each cell
is unmixed in linear light as ``c = f · paint + (1 − f) · background``, the background
(the 9-cell median around it, which the 1-cell strip does not reach) allowed to be
brighter or darker; ``f`` is the paint's share of the cell (:func:`paint_fraction`).  A cell belongs to the rule when it is yellow
(hue 35–75°) and ``f >= min_paint_fraction``.  The threshold follows from the geometry, not
from a scene: a strip one cell wide covers at least half of one cell in every row across
it, wherever it lies, so a cell on the rule has ``f >= 0.5``; ``0.25`` is the midpoint
between no paint (0) and that guaranteed half.  Green grass (hue > 75°), pale soil and dry
grass (little of the paint's saturated yellow in them) stay below it.
The two legs are two straight lines through those cells (RANSAC, then least squares on the
inliers); the corner is their intersection and each leg ends where the paint integrated
across the strip falls to half its level along the leg (:func:`_leg_end`: the 50 % point
of a blurred edge, sub-cell, so the faint last cells of a diagonal strip do not shorten it).  The 3-D length
adds the DEM height difference between corner and end (a leg running down a 35° slope
covers only 0.82 m in plan).  Scale error (001 Table 1): ``max over legs |l − 1 m| / 1 m``.

Cost: O(cells) for the colour test, O(iterations · yellow cells) for RANSAC.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING, Any, Mapping, Sequence

import numpy as np
from scipy import ndimage

from kitegully.io.raster import GridSpec

if TYPE_CHECKING:
    from kitegully.closerange.stage import CloseRangeParams

log = logging.getLogger(__name__)


def _hsv(rgb: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    c = rgb.astype(np.float64) / 255.0
    mx, mn = c.max(axis=0), c.min(axis=0)
    delta = mx - mn
    r, g, b = c
    with np.errstate(invalid="ignore", divide="ignore"):
        h = np.where(mx == r, ((g - b) / delta) % 6, np.where(mx == g, (b - r) / delta + 2, (r - g) / delta + 4)) * 60.0
        s = np.where(mx > 0, delta / mx, 0.0)
    return np.nan_to_num(h), s, mx


def paint_fraction(ortho: np.ndarray, paint_rgb: tuple[float, float, float], gamma: float = 2.2, background_cells: int = 9) -> np.ndarray:
    """Share of each cell covered by a paint of known colour (linear unmixing against the local background).

    In linear light a cell is modelled as ``c − b = f · (p − b) + k · b``: the paint ``p``
    covering a share ``f`` of the cell, and the background ``b`` (the 9-cell median, which a
    1-cell strip does not reach) brighter or darker by ``k`` (a lit grass blade, a shadow:
    brightness changes keep the background's colour).  ``f`` and ``k`` are solved per cell
    by least squares (2 unknowns, 3 bands); without the ``k`` term every bright blade would
    count as a little paint.

    Parameters
    ----------
    ortho : (3, rows, cols) uint8 orthophoto (tone-encoded with ``gamma``).
    paint_rgb : the paint's encoded colour (0–1) in full light.
    gamma : tone curve of the photos (linear light = encoded ** gamma).
    background_cells : window of the median background (cells); wider than twice the strip.

    Returns
    -------
    (rows, cols) float ``f`` (0 = background, 1 = paint).  Cost: O(cells · window²) for the median.
    """
    lin = (ortho[:3].astype(np.float64) / 255.0) ** gamma
    bg = np.stack([ndimage.median_filter(ch, size=background_cells) for ch in lin])
    return unmix_paint(lin, bg, np.asarray(paint_rgb, float) ** gamma)


def unmix_paint(lin: np.ndarray, bg: np.ndarray, paint_lin: np.ndarray) -> np.ndarray:
    """Paint share ``f`` solving ``c − b = f · (p − b) + k · b`` per pixel by least squares (see :func:`paint_fraction`).

    ``lin`` and ``bg`` are (3, ...) linear-light colours of the pixels and their background,
    ``paint_lin`` the paint's (3,) linear colour; returns ``f`` with the shape of ``lin[0]``
    (0 where the two unknowns are not determined).  O(pixels).

    Parameters
    ----------
    lin : ndarray (3, ...)
        Linear-light colours of the pixels.
    bg : ndarray (3, ...)
        Linear-light colours of their background, same shape as ``lin``.
    paint_lin : ndarray (3,)
        Linear colour of the paint.

    Returns
    -------
    ndarray
        Paint share ``f`` of each pixel, shape of ``lin[0]``.
    """
    a1 = paint_lin.reshape((3,) + (1,) * (lin.ndim - 1)).astype(lin.dtype) - bg
    y = lin - bg
    a11, a12, a22 = (a1 * a1).sum(0), (a1 * bg).sum(0), (bg * bg).sum(0)
    b1, b2 = (a1 * y).sum(0), (bg * y).sum(0)
    det = a11 * a22 - a12 * a12
    with np.errstate(invalid="ignore", divide="ignore"):
        f = np.where(det > 1e-12, (a22 * b1 - a12 * b2) / np.where(det > 1e-12, det, 1.0), 0.0)
    return f


def _line_ransac(P: np.ndarray, tol: float, rng: np.random.Generator, iterations: int = 300):
    best = None
    for _ in range(iterations):
        i, j = rng.choice(len(P), 2, replace=False)
        d = P[j] - P[i]
        n = np.linalg.norm(d)
        if n < 5 * tol:
            continue
        d /= n
        dist = np.abs((P[:, 0] - P[i, 0]) * d[1] - (P[:, 1] - P[i, 1]) * d[0])
        inl = dist < tol
        if best is None or inl.sum() > best.sum():
            best = inl
    if best is None:
        return None
    Q = P[best]
    c = Q.mean(axis=0)
    _, _, Vt = np.linalg.svd(Q - c)
    d = Vt[0]
    dist = np.abs((P[:, 0] - c[0]) * d[1] - (P[:, 1] - c[1]) * d[0])
    return c, d, dist < tol


def _leg_end(f: np.ndarray, corner: np.ndarray, d: np.ndarray, far: float) -> float:
    """Distance (cells) from the corner to a leg's end: where the paint across the strip falls to half its level.

    The paint share ``f`` is integrated across the strip (±2 cells) at 0.25-cell steps
    along the leg; the level is its median over the leg's middle (20–80 % of the farthest
    rule cell ``far``), and the end is the first outward crossing of half that level after
    ``far − 3`` cells, interpolated linearly (the 50 % point of a blurred step is its edge,
    independent of the blur).  Falls back to ``far + 0.5`` (the farthest cell's outer edge)
    when no crossing is found.
    """
    nrm = np.array([-d[1], d[0]])
    t = np.arange(0.0, far + 8.0, 0.25)
    a = np.arange(-2.0, 2.01, 0.5)
    X = corner[0] + t[:, None] * d[0] + a[None] * nrm[0]
    Y = corner[1] + t[:, None] * d[1] + a[None] * nrm[1]
    vals = ndimage.map_coordinates(np.nan_to_num(f), [Y.ravel() - 0.5, X.ravel() - 0.5], order=1, mode="constant", cval=0.0)
    prof = np.clip(vals.reshape(X.shape), 0.0, None).sum(axis=1) * 0.5
    prof = np.convolve(prof, np.ones(5) / 5, mode="same")  # ±0.5 cell: a decimetre mark is a dip, not an end
    mid = (t >= 0.2 * far) & (t <= 0.8 * far)
    if not mid.any():
        return far + 0.5
    half = 0.5 * float(np.median(prof[mid]))
    start = int(np.searchsorted(t, max(far - 3.0, 0.0)))
    below = np.nonzero(prof[start:] < half)[0]
    if half <= 0 or len(below) == 0 or below[0] == 0:
        return far + 0.5
    j = start + below[0]
    p0, p1 = prof[j - 1], prof[j]
    return float(t[j - 1] + (p0 - half) / max(p0 - p1, 1e-12) * (t[j] - t[j - 1]))


def measure_folding_rule(
    ortho: np.ndarray, dem: np.ndarray, grid: GridSpec, rng: np.random.Generator,
    paint_rgb: tuple[float, float, float] = (0.93, 0.80, 0.20), min_paint_fraction: float = 0.25,
    leg_length_m: float = 1.0, max_plan_angle_deg: float = 60.0, gamma: float = 2.2,
) -> dict | None:
    """Lengths of the two legs of the folding rule in an orthophoto + DEM; None if not found.

    Parameters
    ----------
    ortho : (3, rows, cols) uint8; dem : (rows, cols) float (NaN = no data); grid : their grid.
    rng : random stream for RANSAC.
    paint_rgb : the rule's yellow (encoded 0–1, full light).
    min_paint_fraction : least share of a cell covered by the paint (see the module doc: 0.25).
    gamma : tone curve of the orthophoto.
    leg_length_m : nominal leg length ([P] 1 m).
    max_plan_angle_deg : two lines meeting at less than this angle in plan are not the rule.

    Returns
    -------
    dict with ``leg_a_m, leg_b_m, scale_error_pct, corner_xy, end_a_xy, end_b_xy, angle_deg``
    (angle between the legs in plan), or None when fewer than 2 legs of at least half the
    nominal length are found or they meet at less than ``max_plan_angle_deg``.
    """
    h, _, _ = _hsv(ortho[:3])
    f = paint_fraction(ortho, paint_rgb, gamma)
    yellow = (h >= 35) & (h <= 75) & (f >= min_paint_fraction) & np.isfinite(dem)
    # the black decimetre marks and cells where a diagonal 1-cell strip covers less than the
    # threshold split it: group cells less than 2 cells (4 cm) apart, keep the largest group
    grouped = ndimage.binary_dilation(yellow, structure=np.ones((3, 3)), iterations=2)
    lab, n = ndimage.label(grouped, structure=np.ones((3, 3)))
    if n == 0:
        return None
    sizes = np.bincount(lab.ravel())[1:]
    keep = lab == (np.argmax(sizes) + 1)
    rr, cc = np.nonzero(keep & yellow)
    min_cells = 0.5 * leg_length_m / grid.cell
    if len(rr) < 2 * min_cells:
        return None
    P = np.column_stack([cc + 0.5, rr + 0.5]).astype(float)  # (col, row) of cell centres, in cells
    tol = 1.5
    l1 = _line_ransac(P, tol, rng)
    if l1 is None:
        return None
    rest = P[~l1[2]]
    if len(rest) < min_cells:
        return None
    l2 = _line_ransac(rest, tol, rng)
    if l2 is None:
        return None
    (c1, d1, in1), (c2, d2, _) = l1, l2
    in2 = np.abs((P[:, 0] - c2[0]) * d2[1] - (P[:, 1] - c2[1]) * d2[0]) < tol
    A = np.column_stack([d1, -d2])
    if abs(np.linalg.det(A)) < 0.2:  # legs nearly parallel: not the rule
        return None
    s1, _ = np.linalg.solve(A, c2 - c1)
    corner = c1 + s1 * d1
    ends = []
    for d, inl in ((d1, in1 & ~in2), (d2, in2 & ~in1)):
        proj = (P[inl] - corner) @ d
        if len(proj) == 0:
            return None
        far = proj[np.argmax(np.abs(proj))]
        ends.append(corner + _leg_end(f, corner, d * np.sign(far), abs(far)) * d * np.sign(far))
    x0, y0 = grid.x0, grid.y0

    def xy(p):  # (col, row) in cells → map x, y
        return np.array([x0 + p[0] * grid.cell, y0 - p[1] * grid.cell])

    def z_at(p):
        r, c = int(np.clip(np.floor(p[1]), 0, dem.shape[0] - 1)), int(np.clip(np.floor(p[0]), 0, dem.shape[1] - 1))
        win = dem[max(r - 1, 0):r + 2, max(c - 1, 0):c + 2]
        return float(np.nanmedian(win)) if np.isfinite(win).any() else np.nan

    zc = z_at(corner)
    legs = []
    for e in ends:
        plan = np.linalg.norm(xy(e) - xy(corner))
        dz = z_at(e) - zc
        legs.append(float(np.hypot(plan, dz)) if np.isfinite(dz) else float(plan))
    if min(legs) < 0.5 * leg_length_m:
        return None
    cosang = abs(float(d1 @ d2))
    if np.degrees(np.arccos(min(cosang, 1.0))) < max_plan_angle_deg:
        # orthogonal legs stay within ~25° of a right angle in plan on slopes up to 35°;
        # two straight yellow streaks at a shallower angle are not the rule
        return None
    return {
        "leg_a_m": legs[0], "leg_b_m": legs[1],
        "scale_error_pct": 100.0 * max(abs(l - leg_length_m) for l in legs) / leg_length_m,
        "corner_xy": xy(corner).tolist(), "end_a_xy": xy(ends[0]).tolist(), "end_b_xy": xy(ends[1]).tolist(),
        "angle_deg": float(np.degrees(np.arccos(min(cosang, 1.0)))),
    }


def measure_rule(
    photos: Sequence[Any], images: Mapping[str, np.ndarray], sim: Any, ortho: np.ndarray, dem: np.ndarray, grid: GridSpec,
    params: CloseRangeParams, rng_photos: np.random.Generator, rng_ortho: np.random.Generator,
) -> tuple[dict | None, str | None, str]:
    """The folding rule's legs: measured in the photos (triangulated), else in the orthophoto; (rule, method, note).

    ``method`` is ``"photos"``, ``"orthophoto"`` or None (not found); ``note`` says why the
    photos gave no rule (empty when they did).  The photo method is the primary one: the
    2 cm strip is 1–5 px wide in the photos and smeared below any defensible paint share in
    the 2 cm orthophoto (README, closerange); the orthophoto's own threshold (a 1-cell strip
    covers at least half a cell) stays principled, so it is kept as the fallback.

    Parameters
    ----------
    photos : sequence of OrientedPhoto
        Oriented photos of the scene (model frame).
    images : mapping
        RGB photo (rows, cols, 3) uint8 of each photo name.
    sim : Similarity
        Model → survey frame (the sphere similarity).
    ortho : ndarray (3, rows, cols) uint8
        Photogrammetric orthophoto.
    dem : ndarray (rows, cols) float
        Photogrammetric DEM (m, NaN = no data).
    grid : GridSpec
        Grid of ``ortho`` and ``dem``.
    params : CloseRangeParams
        Stage settings; reads the ``rule_*`` settings, ``pole_height_m`` and ``outlier_tolerance_m``.
    rng_photos : Generator
        Random stream for the measurement in the photos.
    rng_ortho : Generator
        Random stream for RANSAC in the orthophoto.

    Returns
    -------
    rule : dict or None
        The legs' measurement; None when the rule is not found.
    method : str or None
        ``"photos"``, ``"orthophoto"`` or None.
    note : str
        Why the photos gave no rule; empty when they did.
    """
    from kitegully.closerange.rule_photos import measure_rule_in_photos

    rule, why = measure_rule_in_photos(photos, images, sim, dem, grid, params.rule_paint_rgb, params.rule_strip_width_m,
                                       params.pole_height_m, params.outlier_tolerance_m, rng_photos)
    if rule is not None:
        log.info("folding rule measured in the photos: legs %.3f m, %.3f m (corner in %d photos, ends in %d, %d; %.2f px rms)",
                 rule["leg_a_m"], rule["leg_b_m"], rule["photos_corner"], rule["photos_a"], rule["photos_b"], rule["rms_px"])
        return rule, "photos", ""
    log.info("folding rule not measured in the photos (%s); trying the orthophoto", why)
    rule = measure_folding_rule(ortho, dem, grid, rng_ortho, params.rule_paint_rgb, params.rule_min_paint_fraction)
    return rule, (None if rule is None else "orthophoto"), why
