"""The folding rule measured where it is sharp: its painted strip in the full-resolution photos, triangulated.

001 measured the rule's legs "in the model".  In the 2 cm orthophoto the 2 cm strip is
smeared below any paint share that could be defended (README, closerange), while in the
photos, 3–14 m away with a 24 mm lens on full frame (800 px focal length at 1200 px), the
strip is 1–5 px wide and its black decimetre marks are visible.  So:

1. **Paint share per pixel** (:func:`photo_paint_share`): the same linear unmixing as in the
   orthophoto (:func:`kitegully.closerange.foldrule.paint_fraction`:
   ``c − b = f · (paint − b) + k · b``), against the per-band median of a window
   ``4 ×`` the widest the strip can appear (its width at the pole's height, the nearest
   the camera comes to the ground): the strip then fills at most a quarter of the window
   (half of it at the corner, where two legs cross), so the median is the background.
   A pixel is paint when it is yellow (hue 35–75°) and ``f >= 0.25``: a strip at least a
   pixel wide covers at least half of one pixel in every line across it, and 0.25 is the
   midpoint between no paint and that half (the orthophoto's argument, per pixel).  Image
   noise (1 DN read, shot noise ~3 DN at 200 DN) moves ``f`` by a few hundredths only.
2. **Two joined segments per photo** (:func:`find_rule_views`): straight segments of paint
   pixels are extracted one after the other (RANSAC scored by the heaviest run without a
   gap longer than a strip width + 2 px at the nearest distance: only the 1 cm black marks,
   half a strip width, interrupt a rule's paint; a decimetre's bridging, before session 10,
   joined yellow grass in line beyond the corner to a leg), then weighted least
   squares; two segments are an "L" when their lines meet at more than 30° (:data:`MIN_LINE_ANGLE_DEG`:
   sharper crossings do not fix the corner) at a point each segment reaches (within twice
   the widest strip).  The corner is
   the lines' intersection (exact for the strip's centre lines); each leg ends where the
   paint integrated across the strip falls to half its level along the leg (the 50 %
   point of a blurred edge, sub-pixel).  An end closer to the image border than the
   background window is not seen (the leg may go on outside the frame).  The two ends are
   labelled by the L's handedness in the image: every camera is above the ground, so a
   planar figure keeps its orientation in all of them and leg A is the same leg in every
   photo.
3. **Triangulation** (:func:`triangulate_rule`) with the SfM model's cameras, in the survey
   frame after the sphere similarity: the corner rays of all L's are grouped without labels
   (:func:`kitegully.closerange.model.triangulate_spheres`, the spheres' ray grouping:
   >= 3 photos agreeing within the tolerance), then the A and B end rays of the L's in the
   winning corner group each (>= 2 photos: the L is identified by then; within twice the
   tolerance: an end is located along the strip less sharply than the corner).  [I] tolerance = the strip's width (2 cm): wherever the
   strip is resolved (>= 1 px) a point on it is located within its width.  The result is
   accepted only where the rule can be: corner and ends on the mapped surface (within the
   dense filter's tolerance of the DEM, inside the crop) and the legs orthogonal within
   the angle two points each within the tolerance allow on a half-length leg
   (``2 atan(2 · tol / (0.5 · leg))``, 9° for 2 cm).  This rejects e.g. the edge of the
   rendered ground against the sky, a straight yellowish "L" off the mapped area.
   Scale error (001 Table 1): ``max over legs |l − 1 m| / 1 m`` with ``l`` the 3-D distance
   corner → end.

The photos are the photographer's files (4:4:4 JPEG) where they are the SfM's pixel grid,
not the SfM's prepared 4:2:0 copies, whose halved chroma erases the colour of a 1–2 px strip
(:func:`kitegully.closerange.photos.original_photos`).

Known bias: the twin draws a 5 mm black half-mark at each leg's end (the decimetre marks
are centred on the decimetres), so the paint ends 5 mm before the rule: the legs measure up
to 0.5 % short.  Not corrected.

Cost per photo: O(pixels) for the median (8-bit, OpenCV) and the unmixing, O(iterations ·
paint pixels) for RANSAC; triangulation O(R²) for R corner rays.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Sequence

import cv2
import numpy as np
from scipy import ndimage

from kitegully.closerange.foldrule import unmix_paint
from kitegully.closerange.model import OrientedPhoto, _ray_point_distance, detection_rays, triangulate_spheres
from kitegully.georef.similarity import Similarity
from kitegully.io.raster import GridSpec

log = logging.getLogger(__name__)

#: hue range of the paint (°): the rule's yellow (49°) mixed with grass or soil stays inside it
PAINT_HUE = (35.0, 75.0)
#: least angle (°) at which two segments' lines may meet to form an L: two lines located to
#: half a pixel and meeting at θ fix their crossing to 0.5 px / sin θ along the bisector, within
#: a strip >= 1 px wide for θ >= 30°.  (A right angle on the ground seen from e above the
#: horizon looks no sharper than 2 atan(sin e): 30° from 15°; the far side's flatter views of
#: a leg pointing at the camera are dropped, they cannot place the corner.)
MIN_LINE_ANGLE_DEG = 30.0


@dataclass(frozen=True)
class RuleView:
    """The rule's "L" in one photo: corner and the ends of legs A and B (px, distorted image coordinates)."""

    photo: int
    corner_uv: np.ndarray
    end_uv: np.ndarray  # (2, 2): A, B
    end_seen: np.ndarray  # (2,) bool: the end lies inside the frame (not cut by the border)
    width_px: float  # the strip's apparent width (paint integrated across it), median of the two legs


def strip_width_px(focal_px: float, strip_width_m: float, nearest_m: float) -> float:
    """Widest the strip can appear (px): its width at the nearest distance the camera comes to the ground.

    Parameters
    ----------
    focal_px : float
        Focal length (px).
    strip_width_m : float
        Width of the painted strip (m).
    nearest_m : float
        Nearest distance from the camera to the ground (m).

    Returns
    -------
    float
        Apparent strip width (px).
    """
    return focal_px * strip_width_m / nearest_m


def photo_paint_share(img: np.ndarray, paint_rgb: Sequence[float], gamma: float, window_px: int,
                      min_share: float = 0.25) -> tuple[np.ndarray, np.ndarray]:
    """Paint share ``f`` per pixel and the paint mask (yellow and ``f >= min_share``) of one photo.

    Parameters
    ----------
    img : (rows, cols, 3) uint8 RGB photo.
    paint_rgb : the paint's encoded colour (0–1).  gamma : the photos' tone curve.
    window_px : odd side of the median background window (see module doc: 4 × the widest strip).
    min_share : least paint share of a paint pixel (module doc: 0.25).

    Returns
    -------
    f : (rows, cols) float; mask : (rows, cols) bool.  Cost O(pixels).
    """
    w = int(window_px) | 1
    lut = ((np.arange(256, dtype=np.float32) / 255.0) ** np.float32(gamma)).astype(np.float32)
    bg = np.stack([lut[cv2.medianBlur(np.ascontiguousarray(img[..., i]), w)] for i in range(3)])
    lin = np.moveaxis(lut[img], -1, 0)
    f = unmix_paint(lin, bg, np.asarray(paint_rgb, np.float32) ** np.float32(gamma)).astype(np.float32)
    # hue in degrees from OpenCV's full-range 8-bit HSV (steps of 1.4°)
    h = cv2.cvtColor(np.ascontiguousarray(img), cv2.COLOR_RGB2HSV_FULL)[..., 0].astype(np.float32) * (360.0 / 256.0)
    return f, (h >= PAINT_HUE[0]) & (h <= PAINT_HUE[1]) & (f >= min_share)


def _longest_run(t: np.ndarray, w: np.ndarray, gap: float) -> tuple[float, np.ndarray]:
    """Weight and member mask of the heaviest run of positions ``t`` along a line with no gap longer than ``gap``."""
    order = np.argsort(t)
    ts, ws = t[order], w[order]
    run = np.concatenate([[0], np.cumsum(np.diff(ts) > gap)])
    weight = np.bincount(run, weights=ws)
    best = int(np.argmax(weight))
    members = np.zeros(len(t), bool)
    members[order[run == best]] = True
    return float(weight[best]), members


def _fit_segment(P: np.ndarray, w: np.ndarray, tol: float, gap: float, rng: np.random.Generator, iterations: int = 600,
                 shortlist: int = 20, tree=None):
    """One straight, contiguous segment through points P (N, 2) weighted by w: RANSAC scored by the heaviest run.

    Hypotheses are lines through a random point and a random neighbour of it within
    ``2 · gap`` (a leg's pixels are neighbours: drawing both points from the whole photo
    would hit a 100-pixel leg among thousands of scattered paint-like pixels once in
    hundreds of draws); the ``shortlist`` with the most inlier weight (within ``tol``) are
    scored by their heaviest run without a gap longer than ``gap``; the winner is refined by
    weighted PCA on its run (twice).  Returns ``(centre, unit direction, member mask)`` or None.
    """
    from scipy.spatial import cKDTree

    n = len(P)
    if n < 2:
        return None
    i = rng.integers(0, n, iterations)
    nb = (tree or cKDTree(P)).query_ball_point(P[i], 2.0 * gap)
    j = np.array([nbi[int(rng.integers(0, len(nbi)))] for nbi in nb])
    d = P[j] - P[i]
    L = np.linalg.norm(d, axis=1)
    ok = L > 2 * tol
    if not ok.any():
        return None
    i, d = i[ok], d[ok] / L[ok, None]
    dist = np.abs((P[None, :, 0] - P[i, 0][:, None]) * d[:, 1][:, None] - (P[None, :, 1] - P[i, 1][:, None]) * d[:, 0][:, None])
    total = ((dist < tol) * w[None]).sum(axis=1)
    best, best_score = None, -1.0
    for h in np.argsort(total)[::-1][:shortlist]:
        inl = np.nonzero(dist[h] < tol)[0]
        score, mem = _longest_run(P[inl] @ d[h], w[inl], gap)
        if score > best_score:
            best_score, best = score, (P[i[h]], d[h], inl[mem])
    c, dd, members = best
    for _ in range(2):
        if len(members) < 2:
            return None
        ww = w[members]
        c = (P[members] * ww[:, None]).sum(0) / ww.sum()
        Q = (P[members] - c) * np.sqrt(ww)[:, None]
        dd = np.linalg.svd(Q, full_matrices=False)[2][0]
        inl = np.nonzero(np.abs((P[:, 0] - c[0]) * dd[1] - (P[:, 1] - c[1]) * dd[0]) < tol)[0]
        _, mem = _longest_run(P[inl] @ dd, w[inl], gap)
        members = inl[mem]
    mask = np.zeros(n, bool)
    mask[members] = True
    return c, dd, mask


def _end_along(f: np.ndarray, origin: np.ndarray, d: np.ndarray, far: float, half_width: float) -> tuple[float, float, bool]:
    """Distance (px) from ``origin`` along ``d`` to the leg's end, the strip's apparent width (px), and whether a crossing was found.

    The paint share is integrated across the strip (±``half_width`` px) at 0.25 px steps
    along the leg (its level over the leg's middle, 20–80 % of ``far``, is the strip's
    apparent width in px); after smoothing over a decimetre mark's length (half that width)
    the end is the first outward crossing of half the level after ``far − width``,
    interpolated (the 50 % point of a blurred edge).
    """
    nrm = np.array([-d[1], d[0]])
    t = np.arange(0.0, far + 4 * half_width + 4.0, 0.25)
    a = np.arange(-half_width, half_width + 1e-9, 0.5)
    X = origin[0] + t[:, None] * d[0] + a[None] * nrm[0]
    Y = origin[1] + t[:, None] * d[1] + a[None] * nrm[1]
    vals = ndimage.map_coordinates(f, [Y.ravel(), X.ravel()], order=1, mode="constant", cval=0.0)
    prof = np.clip(vals.reshape(X.shape), 0.0, None).sum(axis=1) * 0.5
    mid = (t >= 0.2 * far) & (t <= 0.8 * far)
    if not mid.any():
        return far, 0.0, False
    width = float(np.median(prof[mid]))
    k = max(1, int(round(0.5 * width / 0.25)))
    prof = np.convolve(prof, np.ones(k) / k, mode="same")
    half = 0.5 * width
    start = int(np.searchsorted(t, max(far - max(width, 1.0), 0.0)))
    below = np.nonzero(prof[start:] < half)[0]
    if half <= 0 or len(below) == 0 or below[0] == 0:
        return far, width, False
    jj = start + below[0]
    p0, p1 = prof[jj - 1], prof[jj]
    return float(t[jj - 1] + (p0 - half) / max(p0 - p1, 1e-12) * (t[jj] - t[jj - 1])), width, True


def find_rule_views(
    f: np.ndarray, mask: np.ndarray, photo: int, width_max_px: float, window_px: int, rng: np.random.Generator,
    max_segments: int = 8, gap_px: float | None = None,
) -> list[RuleView]:
    """Candidate "L"s of the rule in one photo (see module doc, step 2).

    Straight contiguous segments of paint pixels are extracted one after the other
    (:func:`_fit_segment`, at most ``max_segments``), each at least 3 strip widths long; two
    segments form an L when their lines meet at more than ``MIN_LINE_ANGLE_DEG`` (30°) at a point each segment
    reaches (within twice the widest strip).

    Parameters
    ----------
    f, mask : paint share and paint mask of the photo (:func:`photo_paint_share`).
    photo : index of the photo (kept in the views).
    width_max_px : widest the strip can appear (:func:`strip_width_px`).
    window_px : the background window (an end closer than half of it to the border is not seen).
    rng : RANSAC stream.  max_segments : segments extracted per photo.
    gap_px : longest gap in the paint bridged within a segment (default ``width_max_px + 2``, see the code;
        ``5 · width_max_px`` before session 10, kept for the benchmark's comparison).

    Returns
    -------
    list of :class:`RuleView` (possibly several per photo; the triangulation picks the rule).
    Cost: O(segments · iterations · paint pixels).
    """
    rows, cols = mask.shape
    tol = 0.5 * width_max_px + 1.0  # half the widest strip + 1 px of blur
    join = 2.0 * width_max_px + 2.0
    min_len = 3.0 * width_max_px  # a 1 m leg is 50 strip widths; seen end-on from the far side still ~12 px
    # the paint is interrupted only by the black marks, 1 cm long (half a strip width): at the
    # nearest distance <= width_max_px / 2, plus 1 px of blur at each side; bridge twice that,
    # a strip width + 2 px.  (It was one mark *spacing*, a decimetre = 5 strip widths, for the
    # aliasing drop-outs of the session-9 twin's texture-painted rule; a rigid rule composited
    # with coverage, like a lens's blurred image, has none, and a decimetre of bridging joined
    # the rule with yellow grass beyond its corner: scene 03, benchmarks/closerange_rule_diagnosis.py.)
    gap = width_max_px + 2.0 if gap_px is None else float(gap_px)
    rr, cc = np.nonzero(mask)
    if len(rr) < min_len:
        return []
    P = np.column_stack([cc, rr]).astype(float)
    w = np.clip(f[rr, cc], 0.0, 1.0)
    left = np.ones(len(P), bool)
    segs = []
    for _ in range(max_segments):
        idx = np.nonzero(left)[0]
        if len(idx) < min_len:
            break
        sg = _fit_segment(P[idx], w[idx], tol, gap, rng)
        if sg is None:
            break
        c, d, mem = sg
        members = idx[mem]
        left[members] = False
        t = (P[members] - c) @ d
        if t.max() - t.min() >= min_len:
            segs.append((c, d, c + t.min() * d, c + t.max() * d))
    views = []
    margin = 0.5 * window_px
    for a in range(len(segs)):
        for b in range(a + 1, len(segs)):
            (c1, d1, p1, q1), (c2, d2, p2, q2) = segs[a], segs[b]
            if np.degrees(np.arccos(min(abs(float(d1 @ d2)), 1.0))) < MIN_LINE_ANGLE_DEG:
                continue
            corner = c1 + np.linalg.solve(np.column_stack([d1, -d2]), c2 - c1)[0] * d1
            legs = []
            for p, q in ((p1, q1), (p2, q2)):
                near, far_pt = (p, q) if np.linalg.norm(p - corner) < np.linalg.norm(q - corner) else (q, p)
                if np.linalg.norm(near - corner) > join:
                    break
                v = far_pt - corner
                legs.append((v / np.linalg.norm(v), float(np.linalg.norm(v))))
            if len(legs) < 2 or not (margin <= corner[0] <= cols - 1 - margin and margin <= corner[1] <= rows - 1 - margin):
                continue
            ends, seen, widths = [], [], []
            for d, far in legs:
                s_, width, crossed = _end_along(f, corner, d, far, tol)
                e = corner + s_ * d
                inside = margin <= e[0] <= cols - 1 - margin and margin <= e[1] <= rows - 1 - margin
                ends.append(e)
                seen.append(bool(crossed and inside))
                widths.append(width)
            (da, _), (db, _) = legs
            if da[0] * db[1] - da[1] * db[0] < 0:  # handedness (u right, v down): B is A turned by +90° in the image
                ends, seen = ends[::-1], seen[::-1]
            views.append(RuleView(photo, corner, np.array(ends), np.array(seen), float(np.median(widths))))
    return views


def _world_rays(photo: OrientedPhoto, uv: np.ndarray, sim: Similarity) -> tuple[np.ndarray, np.ndarray]:
    o, d = detection_rays(photo, uv)
    return sim.apply(o), d @ sim.R.T


def _angular_point(O: np.ndarray, D: np.ndarray, X0: np.ndarray, iterations: int = 3) -> np.ndarray:
    """Point minimising the squared *angular* distances to the rays (each ray weighted by 1 / range²).

    Pixel errors are alike in every photo, so a far ray's metric error is larger in
    proportion to its range; the plain least-squares point (metric distances,
    :func:`kitegully.closerange.model._least_squares_point`) would give a far, blurred view
    the weight of a near, sharp one.  Ranges from the previous estimate (``X0`` first).
    """
    X = np.asarray(X0, float)
    for _ in range(iterations):
        r2 = np.maximum(np.sum((X - O) ** 2, axis=1), 1e-12)
        A = np.zeros((3, 3))
        b = np.zeros(3)
        for o, d, w in zip(O, D, 1.0 / r2):
            P = w * (np.eye(3) - np.outer(d, d))
            A += P
            b += P @ o
        X = np.linalg.solve(A, b)
    return X


def _group_point(O: np.ndarray, D: np.ndarray, pid: np.ndarray, tol: float, min_rays: int):
    """Largest group of rays (distinct photos) meeting within ``tol``: (point, member indices) or None."""
    if len(O) < min_rays:
        return None
    found = triangulate_spheres(O, D, pid, tol, min_rays)
    if not found:
        return None
    X, members = found[0]
    return _angular_point(O[members], D[members], X), members


def triangulate_rule(
    views: Sequence[RuleView], photos: Sequence[OrientedPhoto], sim: Similarity, dem: np.ndarray, grid: GridSpec,
    tolerance_m: float, surface_tolerance_m: float, leg_length_m: float = 1.0, min_rays: int = 3, min_rays_end: int = 2,
) -> tuple[dict | None, str]:
    """Corner and leg ends of the rule triangulated in the survey frame from the L's seen in the photos.

    Parameters
    ----------
    views : the L's of all photos (:func:`find_rule_views`).
    photos : the oriented photos (``views[i].photo`` indexes them).  sim : model → survey frame.
    dem, grid : the photogrammetric DEM and its grid (the rule lies on it, inside the crop).
    tolerance_m : ray–point distance of the corner ([I] the strip's width); a leg end gets twice
        it ([I] an end is located along the strip less sharply than the corner, which two
        straight lines fix: its blurred edge, the black end mark and a sub-pixel strip's
        dropouts put each photo's end within a strip width, so two rays within twice that).
    surface_tolerance_m : largest height of a rule point off the DEM.
    leg_length_m : nominal leg ([P] 1 m).  min_rays : fewest photos of the corner ([I] 3, as the spheres:
        the corner identifies the rule).  min_rays_end : fewest photos of a leg end, among those
        that saw the corner ([I] 2: the L is identified already, and two rays from different
        photos meeting within the tolerance are themselves the check).

    Returns
    -------
    (result or None, why).  The result has ``leg_a_m, leg_b_m, scale_error_pct, corner_xyz,
    end_a_xyz, end_b_xyz, angle_deg, photos_corner, photos_a, photos_b, rms_px`` and the photo
    indices whose rays made each point (``photo_ids_corner, photo_ids_a, photo_ids_b``; the
    corner's views, indices into ``views``: ``view_ids_corner``).
    """
    if not views:
        return None, "no photo shows two joined straight strips of the rule's paint"
    O, D, pid = [], [], []
    for v in views:
        o, d = _world_rays(photos[v.photo], v.corner_uv, sim)
        O.append(o[0])
        D.append(d[0])
        pid.append(v.photo)
    O, D, pid = np.array(O), np.array(D), np.array(pid)
    groups = triangulate_spheres(O, D, pid, tolerance_m, min_rays)
    if not groups:
        return None, f"the corners of the {len(views)} L(s) found in {len(set(pid.tolist()))} photo(s) do not meet in {min_rays} photos"
    max_angle = 2.0 * np.degrees(np.arctan(2.0 * tolerance_m / (0.5 * leg_length_m)))
    why = ""
    for corner, members in groups:
        corner = _angular_point(O[members], D[members], corner)
        ends, n_end, rays_used, used = [], [], [(O[members], D[members], corner)], []
        for k in (0, 1):
            vs = [views[m] for m in members if views[m].end_seen[k]]
            if len(vs) < min_rays_end:
                break
            Oe, De = zip(*(_world_rays(photos[v.photo], v.end_uv[k], sim) for v in vs))
            Oe, De = np.concatenate(Oe), np.concatenate(De)
            g = _group_point(Oe, De, np.array([v.photo for v in vs]), 2.0 * tolerance_m, min_rays_end)
            if g is None:
                break
            ends.append(g[0])
            n_end.append(len(g[1]))
            used.append([int(vs[i].photo) for i in g[1]])
            rays_used.append((Oe[g[1]], De[g[1]], g[0]))
        if len(ends) < 2:
            why = f"a corner seen in {len(members)} photos, but its leg ends are not both seen in {min_rays_end} photos"
            continue
        pts = np.vstack([corner, ends])
        r, c = grid.rowcol(pts[:, 0], pts[:, 1])
        r, c = np.floor(np.asarray(r)).astype(int), np.floor(np.asarray(c)).astype(int)
        inside = (r >= 0) & (r < dem.shape[0]) & (c >= 0) & (c < dem.shape[1])
        z = np.full(3, np.nan)
        z[inside] = dem[r[inside], c[inside]]
        if not (np.isfinite(z).all() and np.abs(pts[:, 2] - z).max() <= surface_tolerance_m):
            why = "the triangulated L is off the mapped surface (not the rule)"
            continue
        va, vb = ends[0] - corner, ends[1] - corner
        la, lb = float(np.linalg.norm(va)), float(np.linalg.norm(vb))
        angle = float(np.degrees(np.arccos(np.clip(va @ vb / max(la * lb, 1e-12), -1, 1))))
        if abs(angle - 90.0) > max_angle or min(la, lb) < 0.5 * leg_length_m or max(la, lb) > 1.5 * leg_length_m:
            why = f"the triangulated L (legs {la:.2f} m, {lb:.2f} m at {angle:.0f}°) is not the rigid right-angled rule"
            continue
        # residuals in px: distance of each ray from its point over the range, times the focal length
        fpx = float(np.median([p.camera.f for p in photos]))
        res = np.concatenate([_ray_point_distance(o, d, X[None])[0] / np.linalg.norm(X - o, axis=1) for o, d, X in rays_used]) * fpx
        return {
            "leg_a_m": la, "leg_b_m": lb,
            "scale_error_pct": 100.0 * max(abs(la - leg_length_m), abs(lb - leg_length_m)) / leg_length_m,
            "corner_xyz": corner.tolist(), "end_a_xyz": ends[0].tolist(), "end_b_xyz": ends[1].tolist(),
            "angle_deg": angle, "photos_corner": int(len(members)), "photos_a": n_end[0], "photos_b": n_end[1],
            "rms_px": float(np.sqrt(np.mean(res ** 2))),
            "photo_ids_corner": [int(views[m].photo) for m in members], "photo_ids_a": used[0], "photo_ids_b": used[1],
            "view_ids_corner": [int(m) for m in members],
        }, ""
    return None, why


def measure_rule_in_photos(
    photos: Sequence[OrientedPhoto], images: dict[str, np.ndarray], sim: Similarity, dem: np.ndarray, grid: GridSpec,
    paint_rgb: Sequence[float], strip_width_m: float, nearest_m: float, surface_tolerance_m: float,
    rng: np.random.Generator, gamma: float = 2.2, min_share: float = 0.25, leg_length_m: float = 1.0,
) -> tuple[dict | None, str]:
    """The folding rule's legs measured in the photos and triangulated (module doc); (result or None, why not).

    Parameters
    ----------
    photos, images : oriented photos and their pixels (RGB uint8, by name).
    sim : model → survey frame (the sphere similarity).  dem, grid : the photogrammetric DEM.
    paint_rgb : the rule's yellow.  strip_width_m : [P] 2 cm.
    nearest_m : nearest distance of a camera to the ground ([I] the pole's height).
    surface_tolerance_m : largest height of a rule point off the DEM.
    rng : RANSAC stream.  gamma : tone curve.  min_share : least paint share of a paint pixel.

    Returns
    -------
    (dict as :func:`triangulate_rule`'s plus ``views``, the number of L's found, and
    ``photos_with_l``; or None), and the reason when None.
    Cost: O(photos · pixels).
    """
    views = []
    for k, ph in enumerate(photos):
        wmax = strip_width_px(ph.camera.f, strip_width_m, nearest_m)
        window = int(np.ceil(4.0 * wmax)) | 1
        f, mask = photo_paint_share(images[ph.name], paint_rgb, gamma, window, min_share)
        views += find_rule_views(f, mask, k, wmax, window, rng)
    log.info("folding rule: %d candidate L(s) in %d of %d photos", len(views), len({v.photo for v in views}), len(photos))
    tol = strip_width_m
    res, why = triangulate_rule(views, photos, sim, dem, grid, tol, surface_tolerance_m, leg_length_m)
    if res is not None:
        res["views"] = len(views)
        res["photos_with_l"] = len({v.photo for v in views})
    return res, why
