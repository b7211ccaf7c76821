"""Image measurements of a stereo pair: printed frame marks and tie points, found in the photographs.

Frame marks (absolute orientation). Each of the 10 marks is a printed target: a white disc of
diameter ``D`` in the middle of a black square plate of side ``plate_ratio·D``
(:class:`MarkDesign`). :class:`PrintedMarks` puts them into the twin's scene (plates
ray-cast by the renderer, a reflectance for each pixel that sees one). :func:`locate_marks` finds
them in a photograph as target-measuring software does:

1. *prediction*: each mark's surveyed coordinates projected through the calibrated camera at
   the rig's nominal pose (H, B, aimed at the box): off by the rig's unknown tilts (tens of px);
2. *coarse location*: normalised cross-correlation of a disc-on-black template of the predicted
   size within a gate of half the smallest predicted mark spacing (so the gate never reaches a
   neighbour's disc), integer peak;
3. *sub-pixel centre*: iterated intensity-weighted centroid of ``I − b`` over a circular window
   of radius ``r + 2`` px (the disc, its one-pixel edge ramp and one pixel for the coarse
   location's error), ``b`` the median of the black annulus ``r + 2 … 2r`` px.

Why the weighted centroid and not an ellipse fit or a sub-pixel template peak: for a disc of
≥ 10 px diameter the centroid uses every pixel of the target (precision ≈ σ_noise·√Σ(x−x̄)²/Σw,
a few thousandths of a pixel at 1 DN noise and ~200 DN contrast), needs no edge model and is
unbiased for any point-symmetric blur; the perspective eccentricity of a 10 mm disc at 2–5 m
(≈ r²·sin 2θ / (2·distance) ≈ 1 µm) is far below a pixel's 0.4–0.9 mm. A template peak
interpolated by a parabola carries the pixel-locking bias the centroid avoids.

A mark counts as found only if its disc stands out of the black annulus by more than 5 × the
annulus noise (a 5σ detection) and its window lies wholly inside the rendered image; otherwise
:func:`locate_marks` raises one :class:`InputError` sentence.

Tie points (relative orientation): :func:`sift_tie_points`, OpenCV SIFT (Lowe 2004) on both
photographs, nearest two neighbours by FLANN, Lowe's ratio test 0.8 [P]; the coplanarity RANSAC
of :func:`kitegully.stereo.rectify.relative_orientation` then keeps the inliers.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
import numpy as np

from kitegully import InputError
from kitegully.evaluate.dem import nmad
from kitegully.twin.camera import Camera, Pose

log = logging.getLogger(__name__)

#: Lowe's ratio test (Lowe 2004, Fig. 11) [P]: rejects 90 % of false matches, < 5 % of correct ones.
SIFT_RATIO = 0.8
#: Detection threshold of a mark, in units of the black annulus' noise σ [I]: a 5σ detection.
MARK_DETECTION_SIGMA = 5.0


@dataclass(frozen=True)
class MarkDesign:
    """A printed frame mark: a white disc on a black square plate.

    Attributes
    ----------
    diameter_m : float
        Disc diameter (m).
    plate_ratio : float
        Plate side / disc diameter. [I] 2.4: the black annulus from ``r + 2`` px to ``2r`` px
        that gives the background level fits inside the plate's half side ``1.2·D``.
    white, black : float
        Reflectances of the print. [I] 0.90 (matte white paper) and 0.05 (black toner); the
        soil texture stays within 0.05–0.60, so the disc is the brightest thing in its gate.
    """

    diameter_m: float
    plate_ratio: float = 2.4
    white: float = 0.90
    black: float = 0.05

    def __post_init__(self) -> None:
        if not (self.diameter_m > 0 and self.plate_ratio > 2.0):
            raise InputError(f"frame marks: diameter {self.diameter_m} m must be positive and the plate more than twice as wide "
                             f"(plate_ratio {self.plate_ratio})")


@dataclass(frozen=True)
class PrintedMarks:
    """The frame marks of a scene: centres (N × 3, m, z up) on plates parallel to a plane of slope ``dz_dy``."""

    xyz: np.ndarray
    design: MarkDesign
    dz_dy: float = 0.0

    @property
    def half_plate_m(self) -> float:
        """Half the side of a plate (m): ``plate_ratio · diameter_m / 2``."""
        return 0.5 * self.design.plate_ratio * self.design.diameter_m

    def intersect(self, C: np.ndarray, d: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Ray-cast the plates: rays ``C + t·d`` (``d`` … × 3 world directions) whose plate hit is nearer than ``t``.

        Each plate is an opaque square (side ``plate_ratio·D``) through its mark, parallel to the plane of
        slope ``dz_dy``; its top is intersected exactly (no fixed-point iteration, which fails at the
        plate's 1 cm step when the step shifts the ray by more than the plate's margin around the disc).

        Parameters
        ----------
        C : ndarray (3,)
            Origin of the rays, the camera centre (world, m).
        d : ndarray (..., 3)
            World directions of the rays.
        t : ndarray (...)
            Ray parameter of the current hit (the surface); a plate hit replaces it only where nearer.

        Returns
        -------
        (ndarray, ndarray)
            The nearer ray parameter and the index of the plate hit (−1: none). O(rays · marks).
        """
        t = np.array(t, float, copy=True)
        idx = np.full(t.shape, -1, np.int32)
        h = self.half_plate_m
        for i, (cx, cy, cz) in enumerate(self.xyz):
            # z = cz + dz_dy (y − cy) along the ray: C_z + s d_z = cz + dz_dy (C_y + s d_y − cy)
            with np.errstate(divide="ignore", invalid="ignore"):
                s = (cz + self.dz_dy * (C[1] - cy) - C[2]) / (d[..., 2] - self.dz_dy * d[..., 1])
            x, y = C[0] + s * d[..., 0], C[1] + s * d[..., 1]
            hit = (s > 0) & (s < t) & (np.abs(x - cx) <= h) & (np.abs(y - cy) <= h)
            t[hit] = s[hit]
            idx[hit] = i
        return t, idx

    def paint(self, image: np.ndarray, x: np.ndarray, y: np.ndarray, ground_px_m: np.ndarray, idx: np.ndarray) -> np.ndarray:
        """Overwrite the pixels whose ray hits a plate (``idx`` ≥ 0, from :meth:`intersect`) with the print (0–255), in place.

        The disc edge is a linear ramp one ground pixel wide: the area integral of a box pixel over a
        straight edge, so the image of the disc is anti-aliased as a sensor's would be.

        Parameters
        ----------
        image : ndarray
            Image to paint (0–255); changed in place.
        x, y : ndarray
            World x and y (m) of each pixel's ray hit, the shape of ``image``.
        ground_px_m : ndarray
            Ground pixel size at each pixel (m): the width of the disc edge's ramp.
        idx : ndarray of int
            Index of the plate each pixel's ray hits (−1: none), from :meth:`intersect`.

        Returns
        -------
        ndarray
            ``image``, with the print on the pixels that see a plate.
        """
        on = idx >= 0
        if on.any():
            c = self.xyz[idx[on]]
            rho = np.hypot(x[on] - c[:, 0], y[on] - c[:, 1])
            cover = np.clip(0.5 + (0.5 * self.design.diameter_m - rho) / ground_px_m[on], 0.0, 1.0)
            d = self.design
            image[on] = 255.0 * (d.black + (d.white - d.black) * cover)
        return image

    def corners(self) -> np.ndarray:
        """Plate corners (4N × 3, m): what a render window must contain."""
        h = self.half_plate_m
        out = [(cx + a, cy + b, cz + self.dz_dy * b) for cx, cy, cz in self.xyz for a in (-h, h) for b in (-h, h)]
        return np.array(out, float)


@dataclass(frozen=True)
class MarkMeasurement:
    """Image positions of the marks (N × 2, px) with, per mark, the centroid's precision from the image noise (px)."""

    uv: np.ndarray
    sigma_px: np.ndarray
    contrast_dn: np.ndarray
    noise_dn: np.ndarray


def predict_marks(camera: Camera, pose: Pose, marks_xyz: np.ndarray, diameter_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Predicted image positions (N × 2) and disc radii (px) of the marks at a nominal pose.

    Parameters
    ----------
    camera : Camera
        Calibrated camera (distortion included in the projection).
    pose : Pose
        The nominal pose.
    marks_xyz : ndarray (N, 3)
        Mark centres (world, m).
    diameter_m : float
        Disc diameter (m).

    Returns
    -------
    uv : ndarray (N, 2)
        Predicted positions (px).
    radius_px : ndarray (N,)
        Disc radii (px): ``diameter_m / 2 · f`` over each mark's distance from the camera centre.
    """
    uv = camera.project(np.asarray(marks_xyz, float), pose)
    dist = np.linalg.norm(np.asarray(marks_xyz, float) - pose.C, axis=1)
    return uv, 0.5 * diameter_m * camera.f / dist


def _template(r: float) -> np.ndarray:
    n = int(np.ceil(2.0 * r)) + 1
    yy, xx = np.mgrid[-n:n + 1, -n:n + 1].astype(np.float32)
    return np.clip(0.5 + r - np.hypot(xx, yy), 0.0, 1.0).astype(np.float32)


def _centroid(img: np.ndarray, c: np.ndarray, r: float, iterations: int = 3):
    """Iterated intensity-weighted centroid of ``img − b`` in a radius ``r + 2`` window around ``c``."""
    rw, ra = r + 2.0, 2.0 * r
    n = int(np.ceil(ra)) + 1
    h, w = img.shape
    for _ in range(iterations):
        u0, v0 = int(round(c[0])), int(round(c[1]))
        if u0 - n < 0 or v0 - n < 0 or u0 + n >= w or v0 + n >= h:
            return None
        patch = img[v0 - n:v0 + n + 1, u0 - n:u0 + n + 1].astype(np.float64)
        if not np.isfinite(patch).all():
            return None
        yy, xx = np.mgrid[v0 - n:v0 + n + 1, u0 - n:u0 + n + 1].astype(np.float64)
        rho = np.hypot(xx - c[0], yy - c[1])
        ann = patch[(rho > rw) & (rho <= ra)]
        b = float(np.median(ann))
        noise = nmad(ann)
        win = rho <= rw
        wgt = patch[win] - b
        s = wgt.sum()
        if not s > 0:
            return None
        c = np.array([(wgt * xx[win]).sum() / s, (wgt * yy[win]).sum() / s])
    inner = patch[rho <= max(r - 1.0, 1.0)]
    contrast = float(np.mean(inner) - b)
    sig = noise * np.sqrt(np.array([((xx[win] - c[0]) ** 2).sum(), ((yy[win] - c[1]) ** 2).sum()])) / s
    return c, float(np.hypot(*sig) / np.sqrt(2)), contrast, noise


def locate_marks(image: np.ndarray, predicted_uv: np.ndarray, radius_px: np.ndarray, side: str) -> MarkMeasurement:
    """Find each printed mark near its predicted position and measure its centre to sub-pixel.

    Parameters
    ----------
    image : ndarray (H, W)
        Photograph (0–255 grey, NaN = no data).
    predicted_uv : ndarray (N, 2)
        Predicted positions (px) from the nominal rig, see :func:`predict_marks`.
    radius_px : ndarray (N,)
        Predicted disc radii (px).
    side : str
        Name of the image, for messages ("left", "right").

    Returns
    -------
    MarkMeasurement

    Notes
    -----
    Cost: O(N · gate²) for the template search; a few ms per mark.
    """
    P = np.asarray(predicted_uv, float)
    R = np.asarray(radius_px, float)
    if len(P) < 2:
        raise InputError(f"frame marks: {len(P)} predicted in the {side} image; locating needs at least 2 "
                         "(the search gate is half their smallest spacing)")
    dd = np.linalg.norm(P[:, None] - P[None], axis=2)
    dd[np.diag_indices(len(P))] = np.inf
    gate = 0.5 * float(dd.min())  # [I] half the smallest spacing: the gate never reaches a neighbour's disc
    img = np.asarray(image, np.float32)
    uv, sig, con, noi = [], [], [], []
    for i, (p, r) in enumerate(zip(P, R)):
        found = search_disc(img, p, float(r), gate)
        if found is None or not found[2] > MARK_DETECTION_SIGMA * max(found[3], 1e-6):
            why = "its window leaves the image or its rendered part" if found is None else (f"the brightest disc there has a contrast of {found[2]:.1f} DN against "
                                                                        f"{found[3]:.1f} DN of noise, below {MARK_DETECTION_SIGMA:g} σ")
            raise InputError(f"frame mark {i + 1} not found in the {side} image within {gate:.0f} px of its predicted position "
                             f"({p[0]:.0f}, {p[1]:.0f}): {why}")
        uv.append(found[0])
        sig.append(found[1])
        con.append(found[2])
        noi.append(found[3])
    return MarkMeasurement(np.array(uv), np.array(sig), np.array(con), np.array(noi))


def search_disc(img: np.ndarray, predicted: np.ndarray, radius_px: float,
                gate_px: float) -> tuple[np.ndarray, float, float, float] | None:
    """Template search for a printed disc within ``gate_px`` of ``predicted``, then its weighted centroid.

    Parameters
    ----------
    img : ndarray
        Grey image (float32; NaN where nothing was rendered).
    predicted : ndarray
        Predicted (u, v) in pixels.
    radius_px, gate_px : float
        Disc radius and search radius in pixels.

    Returns
    -------
    tuple or None
        :func:`_centroid`'s result at the best normalised correlation, or None where the
        search window leaves the image. O(gate² · template) per disc.
    """
    import cv2
    h, w = img.shape
    tpl = _template(radius_px)
    t = tpl.shape[0] // 2
    g = int(np.ceil(gate_px)) + t
    u0, v0 = int(round(predicted[0])), int(round(predicted[1]))
    x0, y0, x1, y1 = max(0, u0 - g), max(0, v0 - g), min(w, u0 + g + 1), min(h, v0 + g + 1)
    if not (x1 - x0 > tpl.shape[1] and y1 - y0 > tpl.shape[0]):
        return None
    win = img[y0:y1, x0:x1]
    fill = np.where(np.isfinite(win), win, np.nanmedian(win) if np.isfinite(win).any() else 0.0).astype(np.float32)
    _, _, _, (pu, pv) = cv2.minMaxLoc(cv2.matchTemplate(fill, tpl, cv2.TM_CCOEFF_NORMED))
    return _centroid(img, np.array([x0 + pu + t, y0 + pv + t], float), radius_px)


def _to_uint8(image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    import cv2

    img = np.asarray(image, np.float32)
    ok = np.isfinite(img)
    u8 = np.clip(np.where(ok, img, 0.0), 0, 255).round().astype(np.uint8)
    # [I] no keypoints within 8 px of the no-data border: SIFT's 16 × 16 px descriptor would straddle it
    mask = cv2.erode(ok.astype(np.uint8), np.ones((17, 17), np.uint8))
    return u8, mask


def sift_tie_points(img_left: np.ndarray, img_right: np.ndarray, ratio: float = SIFT_RATIO) -> tuple[np.ndarray, np.ndarray]:
    """Tie points of a pair from SIFT keypoints matched with Lowe's ratio test (px, distorted image coordinates).

    Parameters
    ----------
    img_left, img_right : ndarray (H, W)
        Photographs (0–255 grey, NaN = no data); converted to 8 bit as a camera's JPEG would be.
    ratio : float
        Lowe's ratio (nearest / second-nearest descriptor distance) [P] 0.8.

    Returns
    -------
    (ndarray, ndarray)
        Matched positions (N × 2) in the left and right image. Outliers remain: the relative
        orientation's RANSAC on the coplanarity condition removes them.

    Notes
    -----
    Cost: SIFT O(pixels) per image plus an approximate (FLANN k-d tree) 2-NN search,
    O(n log n) in the keypoints; a few seconds for a 2 Mpx window.
    """
    import cv2

    sift = cv2.SIFT_create()
    (a, ma), (b, mb) = _to_uint8(img_left), _to_uint8(img_right)
    ka, da = sift.detectAndCompute(a, ma)
    kb, db = sift.detectAndCompute(b, mb)
    if da is None or db is None or len(ka) < 8 or len(kb) < 8:
        raise InputError(f"tie points: SIFT found {len(ka)} keypoints in the left and {len(kb)} in the right image; "
                         "the relative orientation needs at least 8 matched points")
    # FLANN's randomised k-d trees draw from OpenCV's global random stream: seeded here, the tie points are a
    # function of the photographs alone, not of whatever ran before in the process
    cv2.setRNGSeed(0)
    flann = cv2.FlannBasedMatcher({"algorithm": 1, "trees": 4}, {"checks": 64})
    pairs = flann.knnMatch(da, db, k=2)
    good = [p[0] for p in pairs if len(p) == 2 and p[0].distance < ratio * p[1].distance]
    if len(good) < 8:
        raise InputError(f"tie points: only {len(good)} SIFT matches pass the ratio test between the left and right images; "
                         "the relative orientation needs at least 8")
    uv_l = np.array([ka[m.queryIdx].pt for m in good], float)
    uv_r = np.array([kb[m.trainIdx].pt for m in good], float)
    log.info("tie points: %d + %d SIFT keypoints, %d pass the ratio test", len(ka), len(kb), len(good))
    return uv_l, uv_r


def coplanarity_residuals_px(cam_left: Camera, cam_right: Camera, R: np.ndarray, T: np.ndarray,
                             uv_left: np.ndarray, uv_right: np.ndarray) -> np.ndarray:
    """Sampson distance of each tie point to the coplanarity condition, in pixels (≈ its per-coordinate error).

    The Sampson distance is the first-order distance of the 4-vector (x_l, y_l, x_r, y_r) to the
    epipolar variety; with σ per coordinate its RMS over many points is σ (one constrained direction).

    Parameters
    ----------
    cam_left, cam_right : Camera
        Calibrated cameras.
    R, T : ndarray
        Relative orientation, ``x_right = R x_left + T`` (only the direction of T counts).
    uv_left, uv_right : ndarray (N, 2)
        Tie points, distorted pixel positions (px).

    Returns
    -------
    ndarray (N,)
        Signed Sampson distance of each tie point (px), scaled by the mean f of the two cameras.
    """
    from kitegully.stereo.rectify import _normalised, _sampson

    f = 0.5 * (cam_left.f + cam_right.f)
    return f * _sampson(np.asarray(R, float), np.asarray(T, float), _normalised(cam_left, uv_left), _normalised(cam_right, uv_right))
