"""Direct-projection renderer of a textured height field, for stereo tests and benchmarks.

Each pixel's ray (through the camera's distortion) is intersected with ``z = h(x, y)`` by
fixed-point iteration on the ray parameter (converges when the surface slope is small
compared with the viewing angle, as for a soil box seen from above), then the texture is
sampled bilinearly. The texture is band-limited (smallest blob σ ≥ about one ground pixel),
so one sample per pixel does not alias. This is not :mod:`kitegully.twin.render` (kite
photos of a whole site); it is the minimal renderer a calibrated close-range pair needs.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable

import numpy as np

from kitegully.twin.camera import Camera, Pose

if TYPE_CHECKING:
    from kitegully.stereo.measure import PrintedMarks


@dataclass(frozen=True)
class Texture:
    """Reflectance on a north-up grid: ``values[row, col]`` at ``(x0 + (col + .5)·cell, y0 − (row + .5)·cell)``."""

    values: np.ndarray
    x0: float
    y0: float
    cell: float


def soil_texture(rng: np.random.Generator, extent_m: tuple[float, float, float, float], cell_m: float = 2.5e-4,
                 scales_m: tuple[float, ...] = (6e-4, 1.5e-3, 4e-3, 1.2e-2)) -> Texture:
    """Multi-scale random soil-like texture (reflectance 0.05–0.6) covering ``extent_m`` = (xmin, ymin, xmax, ymax).

    Cost: O(cells · len(scales_m)) Gaussian filtering.

    Parameters
    ----------
    rng : Generator
        Draws the white noise each scale is filtered from.
    extent_m : (float, float, float, float)
        Area to cover, (xmin, ymin, xmax, ymax) (m).
    cell_m : float
        Texture cell size (m).
    scales_m : tuple of float
        Gaussian σ of each noise layer (m); every layer is scaled to unit SD before the layers are summed.

    Returns
    -------
    Texture
        Reflectance grid (float32) whose top-left corner is (xmin, ymax).
    """
    import cv2

    xmin, ymin, xmax, ymax = extent_m
    w, h = int(np.ceil((xmax - xmin) / cell_m)), int(np.ceil((ymax - ymin) / cell_m))
    acc = np.zeros((h, w), np.float32)
    for s in scales_m:
        # OpenCV's separable Gaussian (kernel ±4σ, reflected border): same field as scipy's, several times faster
        # large scales are drawn on a coarser grid (≥ 4 cells per σ) and resized: same spectrum, far cheaper
        k = max(1, int(s / cell_m / 4))
        hc, wc = -(-h // k), -(-w // k)
        n = cv2.GaussianBlur(rng.standard_normal((hc, wc)).astype(np.float32), (0, 0), s / cell_m / k, borderType=cv2.BORDER_REFLECT)
        if k > 1:
            n = cv2.resize(n, (wc * k, hc * k), interpolation=cv2.INTER_CUBIC)[:h, :w]
        acc += n / (n.std() + 1e-12)
    acc /= acc.std()
    return Texture(np.clip(0.3 + 0.09 * acc, 0.05, 0.6).astype(np.float32), xmin, ymax, cell_m)


def render_heightfield(camera: Camera, pose: Pose, height: Callable[[np.ndarray, np.ndarray], np.ndarray],
                       texture: Texture, z_start: float = 0.0, iterations: int = 8,
                       noise_dn: float = 0.0, rng: np.random.Generator | None = None,
                       window: tuple[int, int, int, int] | None = None,
                       marks: PrintedMarks | None = None) -> np.ndarray:
    """Render an 8-bit-scaled float image (0–255) of a textured height field.

    Parameters
    ----------
    camera, pose : Camera, Pose
        Inner and exterior orientation.
    height : callable
        ``height(x, y) → z`` (m), vectorised.
    texture : Texture
        Reflectance grid; outside it the image is 0.
    z_start : float
        Plane the ray iteration starts from (m).
    iterations : int
        Fixed-point iterations of the ray–surface intersection.
    noise_dn, rng
        Gaussian image noise (digital numbers) and its generator.
    window : (x0, y0, x1, y1), optional
        Render only this pixel window (end exclusive); the rest of the frame is NaN
        (no data). The stage renders only the part of the frame that sees the box:
        identical pixels there, a fraction of the cost.
    marks : kitegully.stereo.measure.PrintedMarks, optional
        Printed frame marks: each pixel's ray is also intersected with their plates (opaque, on
        top of the surface) and the print replaces the texture where it hits one (disc edge
        anti-aliased over one ground pixel, ``distance / f``).

    Returns
    -------
    ndarray (height, width) float32

    Notes
    -----
    Cost: O(pixels · iterations); about 1 s per 4-megapixel image.
    """
    import cv2

    x0, y0, x1, y1 = window if window is not None else (0, 0, camera.width, camera.height)
    x0, y0, x1, y1 = max(0, int(x0)), max(0, int(y0)), min(camera.width, int(x1)), min(camera.height, int(y1))
    v, u = np.mgrid[y0:y1, x0:x1].astype(np.float64)
    d = camera.rays_camera(u, v) @ pose.R  # camera → world directions
    C = pose.C
    t = (z_start - C[2]) / d[..., 2]
    for _ in range(iterations):
        x, y = C[0] + t * d[..., 0], C[1] + t * d[..., 1]
        t = (height(x, y) - C[2]) / d[..., 2]
    if marks is not None:
        t, on_plate = marks.intersect(C, d, t)  # the plates are opaque and lie on top: exact ray-plane hits
    x, y = C[0] + t * d[..., 0], C[1] + t * d[..., 1]
    mx = ((x - texture.x0) / texture.cell - 0.5).astype(np.float32)
    my = ((texture.y0 - y) / texture.cell - 0.5).astype(np.float32)
    img = cv2.remap(texture.values, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0.0) * 255.0
    if marks is not None:
        img = marks.paint(img.astype(np.float64), x, y, t / camera.f, on_plate).astype(np.float32)
    if noise_dn > 0:
        img = img + (rng if rng is not None else np.random.default_rng(0)).normal(0.0, noise_dn, img.shape).astype(np.float32)
    if window is None:
        return img.astype(np.float32)
    full = np.full((camera.height, camera.width), np.nan, np.float32)
    full[y0:y1, x0:x1] = img
    return full
