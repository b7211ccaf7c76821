"""Synthetic oriented views of analytic textured surfaces, for the dense-matching tests.

An exact heightfield ray caster: each pixel ray is marched from above the highest to below
the lowest surface point in steps shorter than the texture detail, the first crossing is
refined by bisection to 1e-6 m, and the texture is read at the hit point. No renderer from
the rest of the project is used, so these tests depend only on ``kitegully.dense``.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from kitegully.dense.views import OrientedImage, ViewSet


def plane(z0=100.0):
    return lambda x, y: np.full(np.broadcast(x, y).shape, z0)


def slope(z0=100.0, gx=0.3, gy=-0.15):
    return lambda x, y: z0 + gx * x + gy * y


def step(z0=100.0, height=1.5, x_step=0.0):
    return lambda x, y: z0 + np.where(np.asarray(x) > x_step, height, 0.0) + 0.0 * np.asarray(y)


def trench(z0=100.0, depth=0.5, width=0.4, x_centres=(-3.0, 0.0, 3.0)):
    """Straight vertical-walled trenches along y (narrow gully floors) cut into a plane."""
    def f(x, y):
        x, y = np.asarray(x, float), np.asarray(y, float)
        d = np.min([np.abs(x - cx) for cx in x_centres], axis=0)
        return np.where(d < width / 2, z0 - depth, z0) + 0.0 * y
    f.x_centres, f.depth, f.width = x_centres, depth, width
    return f


def pillars(z0=100.0, height=3.0, radius=1.0, centres=((-3.0, -3.0), (3.0, -2.5), (-2.5, 3.0), (2.5, 3.0), (0.0, 0.0))):
    """Vertical-walled cylinders (tree-crown-like objects) standing on a plane."""
    def f(x, y):
        x, y = np.asarray(x, float), np.asarray(y, float)
        d = np.min([np.hypot(x - cx, y - cy) for cx, cy in centres], axis=0)
        return np.where(d < radius, z0 + height, z0) + 0.0 * x + 0.0 * y
    f.centres, f.radius, f.height = centres, radius, height
    return f


class Texture:
    """Random multi-scale pattern: noise fields at 0.025, 0.2 and 1.6 m, Gaussian-smoothed."""

    def __init__(self, rng: np.random.Generator, half_size_m: float = 20.0, cell: float = 0.025):
        n = int(2 * half_size_m / cell) + 1
        self.x0, self.cell, self.n = -half_size_m, cell, n
        f = ndimage.gaussian_filter(rng.normal(size=(n, n)), 2.5) * 6.0
        for scale in (8, 64):
            m = n // scale + 2
            coarse = rng.normal(size=(m, m))
            f += ndimage.zoom(coarse, scale, order=1)[:n, :n] * 0.6
        self.field = (128 + 40 * f / f.std()).clip(5, 250)

    def __call__(self, x, y):
        c = (np.asarray(x) - self.x0) / self.cell
        r = (np.asarray(y) - self.x0) / self.cell
        return ndimage.map_coordinates(self.field, [r, c], order=1, mode="nearest")


def nadir_view(name, C, f=400.0, width=320, height=240, heading_deg=0.0, tilt_deg=(0.0, 0.0)):
    """A camera looking down: image x to the east (heading 0), image y to the south."""
    h = np.radians(heading_deg)
    Rz = np.array([[np.cos(h), np.sin(h), 0], [-np.sin(h), np.cos(h), 0], [0, 0, 1]])
    R = np.diag([1.0, -1.0, -1.0]) @ Rz
    ax, ay = np.radians(tilt_deg)
    Rx = np.array([[1, 0, 0], [0, np.cos(ax), -np.sin(ax)], [0, np.sin(ax), np.cos(ax)]])
    Ry = np.array([[np.cos(ay), 0, np.sin(ay)], [0, 1, 0], [-np.sin(ay), 0, np.cos(ay)]])
    R = Rx @ Ry @ R
    return OrientedImage(name, name + ".png", width, height, f, (width - 1) / 2, (height - 1) / 2, 0.0, 0.0, R, np.asarray(C, float))


def render(view: OrientedImage, surface, texture: Texture, zlim=(95.0, 110.0), step_m=0.02) -> np.ndarray:
    """Grey image (H, W) float32 of ``surface`` seen by ``view``; exact to the bisection."""
    u, v = np.meshgrid(np.arange(view.width, dtype=float), np.arange(view.height, dtype=float))
    x = (u - view.cx) / view.f
    y = (v - view.cy) / view.f
    d = np.stack([x, y, np.ones_like(x)], axis=-1) @ view.R  # camera → world (R^T d)
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    C = view.C
    t_top = (zlim[1] - C[2]) / d[..., 2]
    t_bot = (zlim[0] - C[2]) / d[..., 2]
    run = (t_bot - t_top) * np.hypot(d[..., 0], d[..., 1])
    n = int(np.ceil(max(run.max() / step_m, (zlim[1] - zlim[0]) / 0.1))) + 1
    lo = t_top.copy()
    hit = np.full(t_top.shape, np.nan)
    prev_t = t_top
    for k in range(1, n + 1):
        t = t_top + (t_bot - t_top) * k / n
        g = C[2] + t * d[..., 2] - surface(C[0] + t * d[..., 0], C[1] + t * d[..., 1])
        new = np.isnan(hit) & (g <= 0)
        hit[new] = t[new]
        lo[new] = prev_t[new]
        prev_t = t
    a, b = lo, np.where(np.isnan(hit), t_bot, hit)
    for _ in range(30):
        m = 0.5 * (a + b)
        g = C[2] + m * d[..., 2] - surface(C[0] + m * d[..., 0], C[1] + m * d[..., 1])
        below = g <= 0
        b = np.where(below, m, b)
        a = np.where(below, a, m)
    t = 0.5 * (a + b)
    img = texture(C[0] + t * d[..., 0], C[1] + t * d[..., 1]).astype(np.float32)
    return img


def block(surface, rng, n_sparse=200, extent=6.0, height_m=20.0, spacing=(4.0, 3.0), grid=(3, 3),
          f=400.0, width=320, height=240, z_ground=100.0):
    """A 3×3 (by default) block of nadir views over ``surface`` with sparse tie points.

    Returns the view set, the grey images and the texture. Views look down from
    ``z_ground + height_m``; GSD = height_m / f.
    """
    tex = Texture(rng)
    views = []
    for i in range(grid[0]):
        for j in range(grid[1]):
            cx = (i - (grid[0] - 1) / 2) * spacing[0]
            cy = (j - (grid[1] - 1) / 2) * spacing[1]
            views.append(nadir_view(f"v{i}{j}", (cx, cy, z_ground + height_m), f, width, height,
                                    heading_deg=float(rng.uniform(-5, 5)), tilt_deg=tuple(rng.uniform(-2, 2, 2))))
    g = np.linspace(-3 * extent, 3 * extent, 241)
    zs = surface(g[None, :], g[:, None])
    zlim = (float(zs.min()) - 0.5, float(zs.max()) + 0.5)
    imgs = [render(v, surface, tex, zlim) for v in views]
    xy = rng.uniform(-extent, extent, size=(n_sparse, 2))
    sparse = np.column_stack([xy, surface(xy[:, 0], xy[:, 1])])
    return ViewSet(views, np.zeros(3), sparse), imgs, tex
