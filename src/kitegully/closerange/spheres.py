"""Automatic measurement of white marker spheres (GCPs) in close-range photos (001 sect. 2.2).

A sphere seen by a pinhole camera is bounded by its tangent cone: a circular cone of
half-angle ``alpha = asin(r / D)`` around the ray to its centre.  What makes a sphere a
sphere in a photo, and what the detector uses (brightness alone does not: in scene 05 the
sunlit soil and dry grass are as white as the spheres):

1. **Neutral colour.** White polystyrene reflects all bands alike, lit by the sun or only
   by the sky, so the whole visible disc, its shaded limb included, is grey:
   ``chroma = (max − min) / max`` of the 3 × 3-mean RGB below ``max_chroma`` and the level
   above ``min_level_dn``.  Grass (green, yellow) and sky (blue) are not; bare soil and
   clipped highlights can be.
2. **A disc of the expected size.** Candidate centres are the local maxima of the distance
   transform of the neutral mask (the centre of the largest inscribed circle, robust to a
   neutral neighbour touching the disc).  Along ``n_rays`` rays the mask's exit must lie on
   one circle (within ``max(1.5 px, 15 %)`` of the median) for at least ``min_edge_share``
   of the rays, with the median in ``radius_px``.
3. **The lit, high-contrast arc.** A sunlit sphere's shaded limb is often as dark as the
   grass behind it: an edge found there is noise, and an outline that loses it moves
   the centre towards the sun (the *sun-side bias*: 2–4 cm between rays from opposite sides
   of the ring, DEMs 0–5 cm low).  Along each ray the outline is the steepest whiteness
   step (``min(R, G, B)`` after a Gaussian of ``edge_sigma_px``; parabola peak, sub-pixel)
   within 2.5 px of the mask's exit; it is used only where that step is at least
   ``min_contrast_dn``.  The used rays must span at least ``min_arc_deg``.
4. **The cone fit.** The arc's points become unit rays (distortion removed) and are fitted
   with a circle in a virtual image plane perpendicular to the current centre estimate,
   where the outline of a sphere is exactly a circle of radius ``tan(alpha)`` around the
   centre's image; two iterations move the plane onto the centre.  So the centre is exact
   from a partial arc (no ellipse-centre correction is needed).  Points beyond 3 MAD are
   dropped and the fit repeated; the fit's RMS must stay below ``max_fit_rms_px``.

Each detection also returns the angular radius ``alpha``: with the ray's distance ``D`` in
a model, ``D·sin(alpha)`` is the sphere's radius in model units, the same for every photo of
one sphere and for all spheres (used in :mod:`kitegully.closerange.model` to test 3-D
candidates and the similarity's scale).

Cost: O(pixels) for the mask and its distance transform, plus O(n_rays · ray length) per
candidate (a few hundred candidates per photo in a bright scene).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np
import pandas as pd
from scipy import ndimage

from kitegully import InputError
from kitegully.config import config_section
from kitegully.evaluate.dem import nmad
from kitegully.twin.camera import Camera


@dataclass(frozen=True)
class SphereDetection:
    """Parameters of sphere detection.

    Attributes
    ----------
    max_chroma : float
        Largest ``(max − min) / max`` of the 3 × 3-mean RGB of a sphere pixel. [I] white
        polystyrene is neutral under sun and sky alike; the noise of a 3 × 3 mean at
        ~130 DN (read 1 DN, shot 0.05 DN²/DN: σ ≈ 0.9 DN) moves it by ~0.02, JPEG's
        halved chroma resolution mixes the grass's 0.13–0.3 into the rim pixel; 0.06 keeps
        the disc and excludes green and yellow grass and the blue sky.
    min_level_dn : float
        Least ``max(R, G, B)`` of a sphere pixel. [I] a sphere's shaded side gets the
        diffuse light only (25–30 %, about 125 DN after the tone curve); half of it allows
        for exposure and vignetting, darker grey pixels (deep shadow, where the chroma of
        noise is large) are not sphere.
    radius_px : tuple of float
        Smallest and largest expected image radius (px): ``f·r/D`` over the walk's distances.
    n_rays : int
        Rays from the candidate centre along which the outline is located.
    edge_sigma_px : float
        Gaussian smoothing of the whiteness before the edge search (px).
    min_contrast_dn : float
        Least whiteness step across the outline (mean 1.5–3 px inside minus outside, either
        sign) for an outline point to be used. [I] the lit limb against grass; where the
        shaded limb meets grass as dark as itself the step falls to the texture's scatter
        and the point would pull the centre: such rays are left out (the sun-side bias).
    max_edge_width_px : float
        Largest Gaussian width (px) of the step at an outline point, measured as
        ``|step| / (√(2π) · largest slope)`` after the ``edge_sigma_px`` smoothing. [I] a
        sphere's limb is an occlusion: a true step blurred only by the pixel (σ 0.3 px),
        the optics and the smoothing, √(1 + 0.3² + 0.5²) ≈ 1.15 px at ``edge_sigma_px`` 1;
        brightness edges in the ground's texture are blurred in addition by its sampling
        (a 2 cm orthophoto seen at 3–13 m: 1–3 px), measured 1.2–1.8 px against 0.9–1.25 px
        on the spheres (scene 05); 1.3 separates them. On a real site grass blades are
        sharp too; the test then rests on the other criteria.
    min_arc_deg : float
        Least angular span (deg) of the outline points used, and least share of the rays
        (``min_arc_deg / 360``) that must give such points. [I] a circle fit to an arc below
        a third of the circle trades its radius against its centre (the centre's error grows
        as 1/(1 − cos(arc/2)) times the edge noise); over 120° it stays within ~3× the
        0.1–0.2 px edge noise.
    max_fit_rms_px : float
        Largest RMS distance of the used outline points from the fitted cone (px). [I] a
        sphere's outline is an exact circle on the cone (measured 0.1–0.2 px with noise);
        irregular bright patches fit to 0.3–3 px.
    min_edge_share : float
        Share of the rays whose neutral-mask exit lies on one circle. [I] a disc gives 1;
        a sphere partly hidden by a grass hummock or touched by a neutral neighbour (bare
        soil, a clipped highlight) keeps more than half; irregular neutral patches do not.
    """

    max_chroma: float = 0.06
    min_level_dn: float = 60.0
    radius_px: tuple[float, float] = (4.0, 80.0)
    n_rays: int = 90
    edge_sigma_px: float = 1.0
    min_contrast_dn: float = 40.0
    max_edge_width_px: float = 1.3
    min_arc_deg: float = 120.0
    max_fit_rms_px: float = 0.3
    min_edge_share: float = 0.6

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any]) -> "SphereDetection":
        """Build from a config mapping (keys as the attributes); bad keys or values raise InputError."""
        config_section(cfg, "sphere detection", (), optional=cls.__dataclass_fields__)
        values = {k: (tuple(float(x) for x in v) if k == "radius_px" else type(getattr(cls, k))(v)) for k, v in cfg.items()}
        p = cls(**values)
        if not 0 < p.radius_px[0] < p.radius_px[1]:
            raise InputError(f"sphere detection: radius_px must be two increasing positive radii, got {list(p.radius_px)}")
        if not (0 < p.max_chroma < 1 and 0 < p.min_edge_share <= 1 and p.n_rays >= 12 and 0 < p.min_arc_deg <= 360):
            raise InputError("sphere detection: max_chroma and min_edge_share must be in (0, 1], n_rays at least 12 "
                             "and min_arc_deg in (0, 360]")
        return p


def _whiteness(image: np.ndarray) -> np.ndarray:
    im = np.asarray(image)
    return (im.min(axis=2) if im.ndim == 3 else im).astype(np.float32)


def neutral_mask(image: np.ndarray, max_chroma: float, min_level_dn: float) -> np.ndarray:
    """Pixels whose 3 × 3-mean colour is grey (chroma below ``max_chroma``) and not dark (max >= ``min_level_dn``).

    Parameters
    ----------
    image : ndarray (H, W, 3) or (H, W)
        RGB photo (DN); a single-band image is tested for its level only.
    max_chroma : float
        Largest ``(max − min) / max`` of a grey pixel.
    min_level_dn : float
        Least brightest-band level of a pixel (DN).

    Returns
    -------
    ndarray (H, W) bool
        True for neutral, bright pixels.
    """
    im = np.asarray(image, dtype=np.float32)
    if im.ndim == 2:
        return ndimage.uniform_filter(im, 3) >= min_level_dn
    m = ndimage.uniform_filter(im, (3, 3, 1))
    mx, mn = m.max(axis=2), m.min(axis=2)
    return (mx >= min_level_dn) & (mx - mn < max_chroma * np.maximum(mx, 1e-6))


def _candidate_centres(mask: np.ndarray, rmin: float, rmax: float) -> np.ndarray:
    """(K, 3) ``u, v, r`` of the largest inscribed circles of the mask with radius in [0.7 rmin, 1.3 rmax] (non-max suppressed)."""
    dt = ndimage.distance_transform_edt(mask)
    size = max(3, int(2 * np.floor(0.7 * rmin) + 1))
    peak = (dt == ndimage.maximum_filter(dt, size=size)) & (dt >= 0.7 * rmin) & (dt <= 1.3 * rmax + 1)
    vv, uu = np.nonzero(peak)
    r = dt[vv, uu]
    order = np.argsort(-r, kind="stable")
    uu, vv, r = uu[order], vv[order], r[order]
    keep = np.ones(len(r), dtype=bool)
    for i in range(len(r)):  # a disc's plateau of maxima → one candidate
        if keep[i]:
            near = np.hypot(uu[i + 1:] - uu[i], vv[i + 1:] - vv[i]) < r[i]
            keep[i + 1:] &= ~near
    return np.column_stack([uu[keep], vv[keep], r[keep]]).astype(float)


def _mask_exits(mask: np.ndarray, cands: np.ndarray, dirs: np.ndarray, step: float = 0.5) -> np.ndarray:
    """(K, n_rays) distance (px) along each ray at which the mask ends (first sample outside)."""
    smax = 2.0 * cands[:, 2].max() + 6.0
    s = np.arange(step, smax, step)
    U = cands[:, 0, None, None] + dirs[None, :, 0, None] * s[None, None]
    V = cands[:, 1, None, None] + dirs[None, :, 1, None] * s[None, None]
    inside = ndimage.map_coordinates(mask.astype(np.uint8), [V.ravel(), U.ravel()], order=0, mode="constant", cval=0)
    inside = inside.reshape(U.shape).astype(bool)
    first_out = np.argmax(~inside, axis=2)
    exits = s[first_out] - 0.5 * step
    exits[inside.all(axis=2)] = np.inf
    return exits


def _outline_points(ws: np.ndarray, centre: np.ndarray, dirs: np.ndarray, exits: np.ndarray,
                    halfwidth: float = 2.5, step: float = 0.25) -> tuple[np.ndarray, np.ndarray]:
    """Sub-pixel steepest whiteness step along each ray within ``halfwidth`` of the mask exit; returns (points, contrast)."""
    o = np.arange(-halfwidth - 3.0, halfwidth + 3.0 + step, step)  # offsets from the exit
    s = exits[:, None] + o[None]
    U = centre[0] + dirs[:, :1] * s
    V = centre[1] + dirs[:, 1:] * s
    prof = ndimage.map_coordinates(ws, [V.ravel(), U.ravel()], order=1, mode="nearest").reshape(U.shape)
    g = np.abs(np.diff(prof, axis=1))  # |step| between samples j and j+1, at offset o[j] + step/2
    mid = o[:-1] + 0.5 * step
    g_in = np.where((np.abs(mid) <= halfwidth)[None], g, -1.0)
    i = np.argmax(g_in, axis=1)
    rows = np.arange(len(dirs))
    gm, g0, gp = g[rows, i - 1], g[rows, i], g[rows, np.minimum(i + 1, g.shape[1] - 1)]
    den = gm - 2 * g0 + gp
    with np.errstate(invalid="ignore", divide="ignore"):
        off = np.where(np.abs(den) > 1e-9, 0.5 * (gm - gp) / den, 0.0)
    pos = exits + mid[i] + np.clip(off, -0.5, 0.5) * step
    # contrast: mean whiteness 1.5-3 px inside minus outside the edge (sign: lit limb > 0, dark limb < 0)
    k = np.arange(int(1.5 / step), int(3.0 / step) + 1)
    j_in = np.clip(i[:, None] - k[None], 0, prof.shape[1] - 1)
    j_out = np.clip(i[:, None] + 1 + k[None], 0, prof.shape[1] - 1)
    contrast = prof[rows[:, None], j_in].mean(axis=1) - prof[rows[:, None], j_out].mean(axis=1)
    pts = np.column_stack([centre[0] + dirs[:, 0] * pos, centre[1] + dirs[:, 1] * pos])
    # width of the step: a Gaussian-blurred step of height c has the largest slope c / (σ √(2π))
    with np.errstate(invalid="ignore", divide="ignore"):
        width = np.abs(contrast) / (np.sqrt(2 * np.pi) * np.maximum(g0 / step, 1e-9))
    return pts, contrast, width


def _rays_to_axis(axis: np.ndarray) -> np.ndarray:
    """Rotation whose third row is ``axis`` (camera frame → virtual camera looking along ``axis``)."""
    z = axis / np.linalg.norm(axis)
    ref = np.array([0.0, 1.0, 0.0]) if abs(z[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
    x = np.cross(ref, z)
    x /= np.linalg.norm(x)
    return np.vstack([x, np.cross(z, x), z])


def fit_sphere_outline(rays: np.ndarray, f: float, iterations: int = 3) -> tuple[np.ndarray, float, np.ndarray]:
    """Fit the tangent cone of a sphere to rays through its outline (a partial arc suffices).

    In a virtual image plane (focal length ``f``) perpendicular to the cone's axis the
    outline is a circle of radius ``f·tan(alpha)`` centred on the axis; the circle is fitted
    (Gauss–Newton on geometric distances, centre and radius free) and the plane re-aimed at
    its centre, ``iterations`` times.  The radius is left free on purpose: a Lambertian
    sphere lit from beside or behind the camera is darker in a sub-pixel band at its limb,
    so the steepest step lies 0.1–0.4 px inside the outline all along the lit arc; a free
    radius absorbs that uniform shift, a radius tied to the disc's would turn it into a
    centre shift towards the shade.

    Parameters
    ----------
    rays : (N, 3) directions (camera frame) through the outline points (N >= 3).
    f : focal length (px) that expresses the residuals in pixels.
    iterations : re-aiming steps.

    Returns
    -------
    unit direction of the sphere centre (camera frame), angular radius (rad), residuals (px).
    """
    d = np.asarray(rays, float)
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    axis = d.mean(axis=0)
    axis /= np.linalg.norm(axis)
    rho = 0.0
    for _ in range(iterations):
        R = _rays_to_axis(axis)
        p = d @ R.T
        x, y = f * p[:, 0] / p[:, 2], f * p[:, 1] / p[:, 2]
        # algebraic (Kåsa) start, then Gauss–Newton on the geometric distances
        A = np.column_stack([2 * x, 2 * y, np.ones_like(x)])
        a, b, c = np.linalg.lstsq(A, x * x + y * y, rcond=None)[0]
        rho = float(np.sqrt(max(c + a * a + b * b, 1e-12)))
        for _ in range(6):
            dx, dy = x - a, y - b
            dist = np.maximum(np.hypot(dx, dy), 1e-12)
            r = dist - rho
            J = np.column_stack([-dx / dist, -dy / dist, -np.ones_like(dist)])
            delta = np.linalg.solve(J.T @ J + 1e-12 * np.eye(3), -(J.T @ r))
            a, b, rho = a + delta[0], b + delta[1], rho + delta[2]
            if np.abs(delta).max() < 1e-4:
                break
        axis = R.T @ np.array([a / f, b / f, 1.0])
        axis /= np.linalg.norm(axis)
    res = fit_sphere_outline_residuals(d, axis, float(np.arctan(rho / f)), f)
    return axis, float(np.arctan(rho / f)), res


def _arc_span_deg(angles: np.ndarray) -> float:
    """Angular span (deg) covered by directions ``angles`` (rad): 360 minus the largest gap."""
    if len(angles) < 2:
        return 0.0
    a = np.sort(np.mod(angles, 2 * np.pi))
    gaps = np.diff(np.append(a, a[0] + 2 * np.pi))
    return float(np.degrees(2 * np.pi - gaps.max()))


def detect_spheres(image: np.ndarray, camera: Camera, params: SphereDetection = SphereDetection()) -> pd.DataFrame:
    """Find white spheres in one photo and measure the images of their centres.

    Parameters
    ----------
    image
        (rows, cols, 3) uint8 RGB (or a single band).
    camera
        Intrinsics used to remove distortion (nominal EXIF values suffice for detection;
        the stage passes the self-calibrated ones).
    params
        Detection parameters.

    Returns
    -------
    pandas.DataFrame
        One row per sphere: ``u_px, v_px`` (image of the sphere centre, distorted, pixel
        centres at integers), ``radius_px`` (``f·tan(alpha)``), ``alpha_rad`` (angular
        radius), ``arc_deg`` (span of the outline points used), ``contrast_dn`` (median
        |step| over them), ``fit_rms_px``, ``n_edge_points``.

    Notes
    -----
    O(pixels) + O(candidates · n_rays · radius).
    """
    cols = ["u_px", "v_px", "radius_px", "alpha_rad", "arc_deg", "contrast_dn", "edge_width_px", "fit_rms_px", "n_edge_points"]
    img = np.asarray(image)
    mask = neutral_mask(img, params.max_chroma, params.min_level_dn)
    rmin, rmax = params.radius_px
    cands = _candidate_centres(mask, rmin, rmax)
    if len(cands) == 0:
        return pd.DataFrame(columns=cols)
    ang = np.linspace(0.0, 2 * np.pi, params.n_rays, endpoint=False)
    dirs = np.column_stack([np.cos(ang), np.sin(ang)])
    rows_out = []
    for lo in range(0, len(cands), 256):  # bounded memory for the vectorised ray sampling
        chunk = cands[lo:lo + 256]
        exits = _mask_exits(mask, chunk, dirs)
        med = np.median(np.where(np.isfinite(exits), exits, 1e9), axis=1)
        on_circle = np.abs(exits - med[:, None]) <= np.maximum(1.5, 0.15 * med)[:, None]
        share = on_circle.mean(axis=1)
        good = (share >= params.min_edge_share) & (med >= rmin) & (med <= rmax)
        for k in np.nonzero(good)[0]:
            rows_out.append((chunk[k], exits[k], on_circle[k], med[k]))
    if not rows_out:
        return pd.DataFrame(columns=cols)
    w = _whiteness(img)
    ws = ndimage.gaussian_filter(w, params.edge_sigma_px) if params.edge_sigma_px > 0 else w
    h, wd = w.shape
    found = []
    for cand, exits, on_circle, med in rows_out:
        # re-centre on the exit points of the rays on the circle (the inscribed circle's centre is integer)
        exits = np.where(np.isfinite(exits), exits, med)  # rays that never leave the mask are off the circle anyway
        e = np.column_stack([cand[0] + dirs[:, 0] * exits, cand[1] + dirs[:, 1] * exits])
        centre = e[on_circle].mean(axis=0)
        ex = np.where(on_circle, np.einsum("ij,ij->i", e - centre, dirs), med)  # exits seen from the new centre
        pts, contrast, width = _outline_points(ws, centre, dirs, ex)
        # a sharp, strong step: the occluding limb (soft steps: ground texture, the terminator's ramp)
        use = on_circle & (np.abs(contrast) >= params.min_contrast_dn) & (width <= params.max_edge_width_px)
        use &= (pts[:, 0] >= 2) & (pts[:, 1] >= 2) & (pts[:, 0] <= wd - 3) & (pts[:, 1] <= h - 3)
        if use.sum() < max(6, params.min_arc_deg / 360.0 * params.n_rays) or _arc_span_deg(ang[use]) < params.min_arc_deg:
            continue
        rays = camera.rays_camera(pts[use, 0], pts[use, 1])
        axis, alpha, res = fit_sphere_outline(rays, camera.f)
        mad = nmad(res)
        keep = np.abs(res) <= max(3.0 * mad, 0.1)  # a grass blade across the limb, a leftover texture edge
        if keep.sum() < 6:
            continue
        if not keep.all():
            axis, alpha, res = fit_sphere_outline(rays[keep], camera.f)
        rms = float(np.sqrt(np.mean(res ** 2)))
        r_px = camera.f * np.tan(alpha)
        if rms > params.max_fit_rms_px or not (rmin <= r_px <= rmax) or _arc_span_deg(ang[use][keep]) < params.min_arc_deg:
            continue
        uv = camera.project_camera(axis[None])[0]
        found.append([uv[0], uv[1], r_px, alpha, _arc_span_deg(ang[use][keep]), float(np.median(np.abs(contrast[use][keep]))),
                      float(np.median(width[use][keep])), rms, int(keep.sum())])
    if not found:
        return pd.DataFrame(columns=cols)
    det = pd.DataFrame(found, columns=cols).sort_values("n_edge_points", ascending=False, kind="stable")
    # one row per sphere: candidates of one disc (a plateau split by noise) give the same fit
    keep_rows: list[int] = []
    for i, r in det.iterrows():
        if all(np.hypot(r.u_px - det.at[j, "u_px"], r.v_px - det.at[j, "v_px"]) > 0.5 * r.radius_px for j in keep_rows):
            keep_rows.append(i)
    return det.loc[keep_rows].reset_index(drop=True)


def fit_sphere_outline_residuals(rays: np.ndarray, axis: np.ndarray, alpha: float, f: float) -> np.ndarray:
    """Residuals (px, in the virtual plane at focal length ``f``) of outline rays from the cone (``axis``, ``alpha``).

    Parameters
    ----------
    rays : ndarray (N, 3)
        Directions (camera frame) through the outline points.
    axis : ndarray (3,)
        Unit direction of the cone's axis, the sphere centre (camera frame).
    alpha : float
        Half-angle of the cone (rad).
    f : float
        Focal length (px) that expresses the residuals in pixels.

    Returns
    -------
    ndarray (N,)
        Signed distance of each ray from the cone's circle in the virtual plane (px); positive outside.
    """
    d = np.asarray(rays, float)
    p = d @ _rays_to_axis(axis).T
    return f * np.hypot(p[:, 0], p[:, 1]) / p[:, 2] - f * np.tan(alpha)
