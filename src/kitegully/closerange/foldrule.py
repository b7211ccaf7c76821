"""The folding rule's two 1 m legs measured in the photogrammetric model (001 sect. 2.2, scale check).

The rule (yellow, 2 cm wide, black decimetre marks) is found in the orthophoto by its
colour: yellow (hue 35–75°, value >= ``min_value``) and more saturated than its
surroundings by ``min_saturation`` (a 2 cm rule in 2 cm cells is mixed with the grass
beside it), which neither green grass (hue > 75°) nor pale soil and dry grass reach.
The two legs are two straight lines through those cells (RANSAC, then least squares on the
inliers); the corner is their intersection and each leg ends at its farthest inlier
(+ half a cell: the cell centre lies half a cell inside the painted end).  The 3-D length
adds the DEM height difference between corner and end (a leg running down a 35° slope
covers only 0.82 m in plan).  Scale error (001 Table 1): ``max over legs |l − 1 m| / 1 m``.

Cost: O(cells) for the colour test, O(iterations · yellow cells) for RANSAC.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from kitegully.io.raster import GridSpec


def _hsv(rgb: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    c = rgb.astype(np.float64) / 255.0
    mx, mn = c.max(axis=0), c.min(axis=0)
    delta = mx - mn
    r, g, b = c
    with np.errstate(invalid="ignore", divide="ignore"):
        h = np.where(mx == r, ((g - b) / delta) % 6, np.where(mx == g, (b - r) / delta + 2, (r - g) / delta + 4)) * 60.0
        s = np.where(mx > 0, delta / mx, 0.0)
    return np.nan_to_num(h), s, mx


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


def measure_folding_rule(
    ortho: np.ndarray, dem: np.ndarray, grid: GridSpec, rng: np.random.Generator, min_saturation: float = 0.07,
    min_value: float = 0.45, leg_length_m: float = 1.0, max_plan_angle_deg: float = 60.0,
) -> dict | None:
    """Lengths of the two legs of the folding rule in an orthophoto + DEM; None if not found.

    Parameters
    ----------
    ortho : (3, rows, cols) uint8; dem : (rows, cols) float (NaN = no data); grid : their grid.
    rng : random stream for RANSAC.
    min_saturation : saturation above the 9-cell median of the surroundings.
    min_value : HSV value of the rule's yellow.
    leg_length_m : nominal leg length ([P] 1 m).
    max_plan_angle_deg : two lines meeting at less than this angle in plan are not the rule.

    Returns
    -------
    dict with ``leg_a_m, leg_b_m, scale_error_pct, corner_xy, end_a_xy, end_b_xy, angle_deg``
    (angle between the legs in plan), or None when fewer than 2 legs of at least half the
    nominal length are found or they meet at less than ``max_plan_angle_deg``.
    """
    h, s, v = _hsv(ortho[:3])
    # saturated relative to the surroundings: a 2 cm rule in 2 cm cells is mixed with grass
    # (saturation ~0.45 where the pure paint has 0.78), dry grass is yellowish but pale
    s_bg = ndimage.median_filter(s, size=9)
    yellow = (h >= 35) & (h <= 75) & (s - s_bg >= min_saturation) & (v >= min_value) & np.isfinite(dem)
    # the black decimetre marks split the strip: close them, keep the largest piece
    closed = ndimage.binary_closing(yellow, structure=np.ones((3, 3)), iterations=2) & ndimage.binary_dilation(yellow, iterations=2)
    lab, n = ndimage.label(closed, structure=np.ones((3, 3)))
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
        ends.append(corner + (far + 0.5 * np.sign(far)) * d)
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
