"""Automatic measurement of white marker spheres (GCPs) in close-range photos (001 sect. 2.2).

A sphere seen by a pinhole camera has an ellipse as its outline (the tangent cone cut by
the image plane).  The pipeline per image:

1. **Blobs.** Whiteness ``w = min(R, G, B)`` (white is bright in all three channels; grass
   is dark in B and R, soil in B); pixels with ``w >= white_min_dn`` are grouped into
   8-connected blobs; a blob is a candidate when its area fits the expected radius range
   and it is round (area / area of its moment ellipse >= ``min_fill``).
2. **Sub-pixel edge.** Along ``n_rays`` rays from the blob centroid, the whiteness profile
   is sampled bilinearly at 0.25 px steps (after a Gaussian of ``edge_sigma_px``); the edge
   is the position of the steepest descent, refined by a parabola through the three
   samples around it (gradient-maximum edge, unbiased for a blurred step).
3. **Ellipse.** The edge points (distortion removed with the camera model) are fitted with
   the direct least-squares ellipse (Fitzgibbon, ``cv2.fitEllipseDirect``); points further
   than 3 MAD from it (a grass blade in front, a shaded limb) are dropped and the fit repeated.
4. **Centre.** The ellipse centre is *not* the image of the sphere centre.  The major
   axis is radial (it lies in the plane through the optical axis and the sphere centre);
   its end points are the images of the two tangent rays in that plane, at angles
   ``θ − α`` and ``θ + α`` from the axis, so the sphere centre direction ``θ`` is their
   bisector (exact, needs no distance):
   ``d = normalize(d1/|d1| + d2/|d2|)`` with ``d1,2 = (x1,2, y1,2, 1)`` normalised image
   coordinates.  To first order the shift from ellipse centre to projected centre is
   ``f·α²·tanθ·sec²θ`` (α = r/D angular radius): for a 10 cm sphere at 4 m in a 24 mm
   full-frame view (f = 800 px at 1200 px width) it reaches 0.8 px in the image corners,
   above the 0.5 px target, so the correction is applied.

Cost: O(pixels) for the blob labelling plus O(n_rays · ray length) per blob.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping

import cv2
import numpy as np
import pandas as pd
from scipy import ndimage

from kitegully import InputError
from kitegully.config import config_section
from kitegully.twin.camera import Camera


@dataclass(frozen=True)
class SphereDetection:
    """Parameters of sphere detection.

    Attributes
    ----------
    white_min_dn : float
        Whiteness ``min(R, G, B)`` (8-bit DN) a sphere pixel reaches. [I] the polystyrene
        (reflectance ~0.9) is far above soil (~0.3) and grass (B ~0.1); between them on the
        tone curve; seeds only, the blob then grows to the midpoint of its bright level
        and the local background (hysteresis), so shaded sides and vignetted corners count.
    radius_px : tuple of float
        Smallest and largest expected image radius (px): ``f·r/D`` over the walk's distances.
    min_fill : float
        Blob area / area of its moment ellipse; a disc gives 1, a folding-rule leg or a
        stone's highlight much less.
    n_rays : int
        Rays from the blob centre along which the edge is located.
    edge_sigma_px : float
        Gaussian smoothing before the edge search (px).
    min_contrast_dn : float
        Bright level (90th percentile of the seed) minus the median of the surrounding ring.
        [I] the spheres stand on grass (whiteness ~30 DN) and reach ~200 DN; pebbles and
        sunlit soil grains on bright soil stay below ~60 DN of contrast.
    max_fit_rms_px : float
        Largest RMS distance of the edge points from the fitted ellipse. [I] a sphere's
        outline is an exact ellipse (measured 0.1–0.2 px with noise); irregular bright
        patches fit to 0.3–3 px.
    min_edge_share : float
        Share of the rays whose edge point survives the outlier rejection. [I] a sphere
        hidden over more than a fifth of its outline (a grass hummock in front, the image
        border) is not measured: its visible arc biases the centre (0.7 px seen at 80 %).
    """

    white_min_dn: float = 150.0
    radius_px: tuple[float, float] = (4.0, 80.0)
    min_fill: float = 0.8
    n_rays: int = 90
    edge_sigma_px: float = 1.0
    min_contrast_dn: float = 80.0
    max_fit_rms_px: float = 0.3
    min_edge_share: float = 0.8

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any]) -> "SphereDetection":
        """Build from a config mapping (keys as the attributes); bad keys or values raise InputError."""
        config_section(cfg, "sphere detection", (), optional=cls.__dataclass_fields__)
        values = {k: (tuple(float(x) for x in v) if k == "radius_px" else type(getattr(cls, k))(v)) for k, v in cfg.items()}
        p = cls(**values)
        if not 0 < p.radius_px[0] < p.radius_px[1]:
            raise InputError(f"sphere detection: radius_px must be two increasing positive radii, got {list(p.radius_px)}")
        if not (0 < p.min_fill <= 1 and 0 < p.min_edge_share <= 1 and p.n_rays >= 12):
            raise InputError("sphere detection: min_fill and min_edge_share must be in (0, 1] and n_rays at least 12")
        return p


def _whiteness(image: np.ndarray) -> np.ndarray:
    im = np.asarray(image)
    return (im.min(axis=2) if im.ndim == 3 else im).astype(np.float32)


def _edge_points(w_smooth: np.ndarray, centre: np.ndarray, r0: float, n_rays: int) -> np.ndarray:
    """Steepest-descent positions of ``w_smooth`` along rays from ``centre`` (sub-pixel)."""
    ang = np.linspace(0.0, 2 * np.pi, n_rays, endpoint=False)
    step = 0.25
    s = np.arange(0.5 * r0, 1.5 * r0 + 3.0, step)
    dirs = np.column_stack([np.cos(ang), np.sin(ang)])
    U = centre[0] + dirs[:, :1] * s[None]
    V = centre[1] + dirs[:, 1:] * s[None]
    prof = ndimage.map_coordinates(w_smooth, [V.ravel(), U.ravel()], order=1, mode="nearest").reshape(U.shape)
    g = -np.diff(prof, axis=1)  # descent between consecutive samples
    i = np.argmax(g, axis=1)
    ok = (i > 0) & (i < g.shape[1] - 1)
    rows = np.arange(n_rays)
    gm, g0, gp = g[rows, np.clip(i - 1, 0, None)], g[rows, i], g[rows, np.clip(i + 1, None, g.shape[1] - 1)]
    den = gm - 2 * g0 + gp
    with np.errstate(invalid="ignore", divide="ignore"):
        off = np.where(np.abs(den) > 1e-9, 0.5 * (gm - gp) / den, 0.0)
    pos = s[0] + (i + 0.5 + np.clip(off, -0.5, 0.5)) * step  # g[i] sits between samples i and i+1
    pts = np.column_stack([centre[0] + dirs[:, 0] * pos, centre[1] + dirs[:, 1] * pos])
    h, w = w_smooth.shape
    inside = (pts[:, 0] >= 2) & (pts[:, 1] >= 2) & (pts[:, 0] <= w - 3) & (pts[:, 1] <= h - 3)
    return pts[ok & (g0 > 0) & inside]


def _to_normalised(camera: Camera, uv: np.ndarray) -> np.ndarray:
    xn, yn = camera.undistort((uv[:, 0] - camera.cx) / camera.f, (uv[:, 1] - camera.cy) / camera.f)
    return np.column_stack([xn, yn])


def fit_ellipse(points_px: np.ndarray) -> tuple[tuple[float, float], tuple[float, float], float, float, int]:
    """Direct least-squares ellipse with one 3-MAD outlier rejection round.

    Returns
    -------
    centre (u, v), semi-axes (a >= b), major-axis angle (rad, from +u), RMS distance of the
    kept points (px), number of kept points
    """
    P = np.asarray(points_px, dtype=np.float64)
    keep = np.ones(len(P), dtype=bool)
    for _ in range(2):
        (cu, cv_), (d1, d2), ang = cv2.fitEllipseDirect(P[keep].astype(np.float32))
        res = _ellipse_residual(P, (cu, cv_), (d1 / 2, d2 / 2), np.radians(ang))
        mad = np.median(np.abs(res[keep] - np.median(res[keep]))) * 1.4826
        new = np.abs(res) <= max(3.0 * mad, 0.05)
        if new.sum() < 6 or np.array_equal(new, keep):
            break
        keep = new
    a, b, theta = d1 / 2, d2 / 2, np.radians(ang)
    if b > a:
        a, b, theta = b, a, theta + np.pi / 2
    rms = float(np.sqrt(np.mean(res[keep] ** 2)))
    return (float(cu), float(cv_)), (float(a), float(b)), float(theta), rms, int(keep.sum())


def _ellipse_residual(P, c, axes, theta):
    """Approximate geometric distance of points to an ellipse (algebraic, scaled to px)."""
    ct, st = np.cos(theta), np.sin(theta)
    x = (P[:, 0] - c[0]) * ct + (P[:, 1] - c[1]) * st
    y = -(P[:, 0] - c[0]) * st + (P[:, 1] - c[1]) * ct
    rho = np.sqrt((x / axes[0]) ** 2 + (y / axes[1]) ** 2)
    return (rho - 1.0) * np.sqrt(axes[0] * axes[1])


def sphere_centre_from_ellipse(camera: Camera, centre_n: np.ndarray, a_n: float) -> np.ndarray:
    """Image (px, distorted) of a sphere's centre from its outline ellipse in normalised coordinates.

    ``centre_n`` and ``a_n`` are the ellipse centre and semi-major axis in undistorted
    normalised coordinates.  The major axis is taken along the radial direction (exact for
    a sphere), its end points give the two tangent rays, their bisector the centre ray.
    """
    c = np.asarray(centre_n, dtype=float)
    rad = np.hypot(*c)
    if rad < 1e-12:
        d = np.array([c[0], c[1], 1.0])
    else:
        e = c / rad
        p1, p2 = c - a_n * e, c + a_n * e
        d1 = np.array([p1[0], p1[1], 1.0])
        d2 = np.array([p2[0], p2[1], 1.0])
        d = d1 / np.linalg.norm(d1) + d2 / np.linalg.norm(d2)
    uv = camera.project_camera(d[None])[0]
    return uv


def detect_spheres(image: np.ndarray, camera: Camera, params: SphereDetection = SphereDetection()) -> pd.DataFrame:
    """Find white spheres in one photo and measure the images of their centres.

    Parameters
    ----------
    image
        (rows, cols, 3) uint8 RGB (or a single band).
    camera
        Intrinsics used to remove distortion and to correct the ellipse centre (nominal
        EXIF values suffice: the correction is second order in the intrinsics).
    params
        Detection parameters.

    Returns
    -------
    pandas.DataFrame
        One row per sphere: ``u_px, v_px`` (image of the sphere centre, pixel centres at
        integers), ``ellipse_u_px, ellipse_v_px`` (uncorrected ellipse centre),
        ``semi_major_px, semi_minor_px, fit_rms_px, n_edge_points``.
    """
    w = _whiteness(image)
    mask = w >= params.white_min_dn
    lab, n = ndimage.label(mask, structure=np.ones((3, 3)))
    cols = ["u_px", "v_px", "ellipse_u_px", "ellipse_v_px", "semi_major_px", "semi_minor_px", "fit_rms_px", "n_edge_points"]
    if n == 0:
        return pd.DataFrame(columns=cols)
    rmin, rmax = params.radius_px
    areas = np.bincount(lab.ravel(), minlength=n + 1)
    ws = ndimage.gaussian_filter(w, params.edge_sigma_px) if params.edge_sigma_px > 0 else w
    rows = []
    for k, sl in enumerate(ndimage.find_objects(lab), start=1):
        area = areas[k]
        if sl is None or area < np.pi * rmin ** 2 * 0.5 or area > np.pi * rmax ** 2 * 1.5:
            continue
        # hysteresis: the shaded side of a sphere is darker than the seed threshold; grow the
        # blob into pixels above the midpoint of its bright level and the local background
        r_seed = np.sqrt(area / np.pi)
        pad = int(np.ceil(2.5 * r_seed)) + 3
        r0_, r1_ = max(sl[0].start - pad, 0), min(sl[0].stop + pad, w.shape[0])
        c0_, c1_ = max(sl[1].start - pad, 0), min(sl[1].stop + pad, w.shape[1])
        roi, seed = w[r0_:r1_, c0_:c1_], lab[r0_:r1_, c0_:c1_] == k
        near = ndimage.binary_dilation(seed, iterations=int(np.ceil(1.5 * r_seed)) + 2)
        ring = ~near & ~(lab[r0_:r1_, c0_:c1_] > 0)
        if ring.sum() < 10:
            continue
        bg_level, bright = float(np.median(roi[ring])), float(np.percentile(roi[seed], 90))
        if bright - bg_level < params.min_contrast_dn:
            continue
        mid = 0.5 * (bg_level + bright)
        grown, _ = ndimage.label(roi > mid)
        ids = np.unique(grown[seed])
        region = np.isin(grown, ids[ids > 0])
        vv, uu = np.nonzero(region)
        area = len(uu)
        uu = uu + c0_
        vv = vv + r0_
        cu, cv_ = uu.mean(), vv.mean()
        cov = np.cov(np.vstack([uu, vv]))
        ev = np.linalg.eigvalsh(cov)
        ell_area = 4 * np.pi * np.sqrt(max(ev[0], 1e-9) * ev[1])
        if area / ell_area < params.min_fill:
            continue
        r0 = float(np.sqrt(area / np.pi))
        pts = _edge_points(ws, np.array([cu, cv_]), r0, params.n_rays)
        if len(pts) < 10:
            continue
        # fit in undistorted pixel coordinates (distortion removed, same scale f)
        pn = _to_normalised(camera, pts)
        pu = pn * camera.f + np.array([camera.cx, camera.cy])
        (eu, ev_), (a, b), _, rms, n_kept = fit_ellipse(pu)
        if not (rmin <= b and a <= rmax) or b / a < 0.5 or rms > params.max_fit_rms_px:
            continue
        if n_kept < params.min_edge_share * params.n_rays:
            continue
        centre_n = (np.array([eu, ev_]) - np.array([camera.cx, camera.cy])) / camera.f
        uv = sphere_centre_from_ellipse(camera, centre_n, a / camera.f)
        ell_uv = camera.project_camera(np.array([[centre_n[0], centre_n[1], 1.0]]))[0]
        rows.append([uv[0], uv[1], ell_uv[0], ell_uv[1], a, b, rms, n_kept])
    return pd.DataFrame(rows, columns=cols)
