"""Render all photos of a simulated flight and measure their coverage.

Per image: ray-cast reflectance (:func:`render_reflectance`), motion blur from the camera's
motion during the exposure, exposure/vignetting/noise (:func:`photograph`) and a JPEG with
EXIF. Each image draws its noise from its own generator seeded by ``(seed, index)`` so an
image does not change when others are added. Cost: O(images × pixels).
"""

from __future__ import annotations

import logging
import time
from datetime import datetime
from pathlib import Path
from typing import Sequence

import numpy as np
import pandas as pd

from kitegully.seeds import rng_for
from kitegully.twin.camera import Camera
from kitegully.twin.exif import exif_bytes, write_jpeg
from kitegully.twin.flight import pose_from_row
from kitegully.twin.render import Photographic, Scene, photograph, render_reflectance, surface_height

log = logging.getLogger(__name__)


def blur_vector(camera: Camera, row: pd.Series, ground_point: np.ndarray, exposure_time_s: float) -> np.ndarray:
    """Image motion (px) of ``ground_point`` during the exposure, from the pose rates.

    Parameters
    ----------
    camera : Camera
        The camera.
    row : Series
        One row of the poses table, with the velocity and attitude-rate columns.
    ground_point : ndarray (3,)
        World point (m).
    exposure_time_s : float
        Shutter time (s).

    Returns
    -------
    ndarray (2,)
        Displacement of the point in the image (px) between shutter open and close; 0 where it
        does not project.
    """
    a = camera.project(ground_point[None], pose_from_row(row))[0]
    b = camera.project(ground_point[None], pose_from_row(row, exposure_time_s))[0]
    v = b - a
    return np.where(np.isfinite(v), v, 0.0)


def render_flight(
    scene: Scene,
    camera: Camera,
    poses: pd.DataFrame,
    out_dir: str | Path,
    effects: Photographic,
    seed: int,
    channels: Sequence[int],
    supersampling: int,
    background: Sequence[float],
    jpeg_quality: int,
) -> pd.DataFrame:
    """Render and write every image of ``poses``; returns per-image facts.

    Returns columns ``image, gsd_m`` (median over the image), ``ev_offset, blur_px, hit_fraction, render_s``.

    Parameters
    ----------
    scene : Scene
        The surface and texture.
    camera : Camera
        The camera.
    poses : DataFrame
        True poses, one row per image (``image``, ``timestamp`` and the pose columns).
    out_dir : str or Path
        Folder the JPEGs are written to; created if missing.
    effects : Photographic
        Camera effects.
    seed : int
        Seed of the per-image noise streams.
    channels : sequence of int
        Texture band index of each output channel.
    supersampling : int
        ``s`` gives ``s × s`` rays per pixel.
    background : sequence of float
        Reflectance (0–1) per output channel where a ray misses the surface.
    jpeg_quality : int
        JPEG quality.

    Returns
    -------
    DataFrame
        One row per image.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    rows = []
    t_all = time.perf_counter()
    for i, (_, p) in enumerate(poses.iterrows()):
        t0 = time.perf_counter()
        pose = pose_from_row(p)
        refl, depth = render_reflectance(scene, camera, pose, channels, supersampling, background)
        cy, cx = int(round(camera.cy)), int(round(camera.cx))
        d0 = float(depth[cy, cx])
        # GSD: median over the pixels that see the twin, range along the ray / f
        gsd = float(np.nanmedian(depth)) / camera.f if np.isfinite(depth).any() else float("nan")
        ray = camera.rays_camera(np.array([camera.cx]), np.array([camera.cy]))[0] @ pose.R
        ground = pose.C + ray * (d0 if np.isfinite(d0) else (pose.C[2] - scene.zmin))
        blur = blur_vector(camera, p, ground, effects.exposure_time_s)
        rng = rng_for(seed, i)  # = default_rng([seed, i]), the stream the images were made with
        img, ev = photograph(refl, camera, effects, rng, blur)
        when = datetime.fromisoformat(p["timestamp"])
        write_jpeg(out_dir / p["image"], img, exif_bytes(camera, when, effects.exposure_time_s), jpeg_quality)
        dt = time.perf_counter() - t0
        rows.append(
            dict(
                image=p["image"],
                gsd_m=gsd,
                ev_offset=ev,
                blur_px=float(np.hypot(*blur)),
                hit_fraction=float(np.isfinite(depth).mean()),
                render_s=dt,
            )
        )
        log.info("image %d/%d %s: GSD %.3f m, blur %.2f px, %.1f s", i + 1, len(poses), p["image"], gsd,
                 np.hypot(*blur), dt)
    log.info("rendered %d images in %.1f s", len(poses), time.perf_counter() - t_all)
    return pd.DataFrame(rows)


def _ground_points(scene: Scene, extent, cell_m: float):
    xmin, ymin, xmax, ymax = extent
    xs = np.arange(xmin + cell_m / 2, xmax, cell_m)
    ys = np.arange(ymax - cell_m / 2, ymin, -cell_m)
    X, Y = np.meshgrid(xs, ys)
    Z = surface_height(scene, X, Y)
    zfill = float(np.nanmedian(scene.dsm))
    return xs, ys, np.column_stack([X.ravel(), Y.ravel(), np.where(np.isfinite(Z), Z, zfill)])


def _seen(camera: Camera, poses: pd.DataFrame, P: np.ndarray) -> np.ndarray:
    seen = np.zeros((len(poses), len(P)), dtype=bool)
    for i, (_, p) in enumerate(poses.iterrows()):
        uv = camera.project(P, pose_from_row(p))
        seen[i] = camera.in_image(np.nan_to_num(uv, nan=-1e9))
    return seen


def coverage(
    camera: Camera,
    poses: pd.DataFrame,
    scene: Scene,
    extent: tuple[float, float, float, float],
    cell_m: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, pd.DataFrame]:
    """Images seeing each ground point (occlusion ignored) and forward overlap per image pair.

    Ground points lie on a ``cell_m`` grid over ``extent`` at the DSM height. The forward
    overlap of consecutive images of a strip is the share of image i's ground points also
    seen by image i+1, on a coarser grid that extends past the site (off-site ground at the
    DSM's median height) so images at the strip ends are measured whole. Returns (x
    centres, y centres, counts as rows × cols, overlap table). Cost: O(images × points).

    Parameters
    ----------
    camera : Camera
        The camera.
    poses : DataFrame
        True poses, one row per image (``image``, ``strip``, ``x_m``, ``y_m``, ``z_m`` and the pose columns).
    scene : Scene
        The surface.
    extent : tuple of float
        Site extent ``(xmin, ymin, xmax, ymax)`` (m).
    cell_m : float
        Spacing of the ground points (m).

    Returns
    -------
    xs, ys : ndarray
        x and y of the grid's columns and rows (m); rows run south.
    counts : ndarray (len(ys), len(xs)) int
        Images seeing each ground point.
    overlap : DataFrame
        ``image, next_image, strip, forward_overlap``, one row per consecutive pair on a strip.
    """
    xs, ys, P = _ground_points(scene, extent, cell_m)
    counts = _seen(camera, poses, P).sum(axis=0).reshape(len(ys), len(xs))
    reach = float((poses["z_m"] - scene.zmin).max()) * np.hypot(camera.width, camera.height) / (2 * camera.f)
    big = (poses["x_m"].min() - reach, poses["y_m"].min() - reach, poses["x_m"].max() + reach, poses["y_m"].max() + reach)
    big_cell = max(cell_m, float(np.sqrt((big[2] - big[0]) * (big[3] - big[1]) / 2e5)))
    _, _, Q = _ground_points(scene, big, big_cell)
    seen = _seen(camera, poses, Q)
    rows = []
    strips = poses["strip"].to_numpy()
    for i in range(len(poses) - 1):
        if strips[i] == strips[i + 1] and seen[i].any():
            rows.append(
                dict(image=poses["image"].iloc[i], next_image=poses["image"].iloc[i + 1], strip=int(strips[i]),
                     forward_overlap=float((seen[i] & seen[i + 1]).sum() / seen[i].sum()))
            )
    return xs, ys, counts, pd.DataFrame(rows, columns=["image", "next_image", "strip", "forward_overlap"])


def core_mask(xs: np.ndarray, ys: np.ndarray, extent: tuple[float, float, float, float], buffer_m: float) -> np.ndarray:
    """Boolean (rows × cols) mask of grid points inside ``extent`` shrunk by ``buffer_m``.

    Parameters
    ----------
    xs, ys : ndarray
        x and y of the grid's columns and rows (m).
    extent : tuple of float
        Site extent ``(xmin, ymin, xmax, ymax)`` (m).
    buffer_m : float
        Inward buffer (m).

    Returns
    -------
    ndarray (len(ys), len(xs)) bool
    """
    xmin, ymin, xmax, ymax = extent
    X, Y = np.meshgrid(xs, ys)
    return (X >= xmin + buffer_m) & (X <= xmax - buffer_m) & (Y >= ymin + buffer_m) & (Y <= ymax - buffer_m)


def load_scene(dsm_path: str | Path, texture_path: str | Path, channels: Sequence[str], block: int) -> tuple[Scene, list[int]]:
    """Read the twin's DSM and texture GeoTIFFs into a :class:`Scene`.

    ``channels`` name texture bands by their descriptions (e.g. ``R, G, B, NIR``); a
    texture without descriptions is taken as R, G, B, NIR in that order. Returns the scene
    and the band index of each channel. Memory: DSM + 4/3 × texture.

    Parameters
    ----------
    dsm_path : str or Path
        The DSM GeoTIFF.
    texture_path : str or Path
        The texture GeoTIFF: uint8 reflectance × 255, in the DSM's CRS.
    channels : sequence of str
        Band names of the output channels.
    block : int
        Block size (cells) of the empty-space-skipping grid.

    Returns
    -------
    scene : Scene
    indices : list of int
        Band index of each channel.
    """
    import rasterio

    from kitegully import InputError
    from kitegully.io.raster import read_raster
    from kitegully.twin.render import make_scene

    dsm, grid = read_raster(dsm_path)
    if not np.isfinite(dsm).any():
        raise InputError(f"{dsm_path}: DSM is all nodata")
    tex, tgrid = read_raster(texture_path, band=None)
    if tex.dtype != np.uint8:
        raise InputError(f"{texture_path}: texture must be uint8 reflectance × 255, got {tex.dtype}")
    if tgrid.crs != grid.crs:
        raise InputError(f"{texture_path}: CRS {tgrid.crs} differs from the DSM's {grid.crs}")
    with rasterio.open(texture_path) as src:
        desc = [d.strip().upper() if d else "" for d in src.descriptions]
    if not any(desc):
        desc = ["R", "G", "B", "NIR"][: tex.shape[0]]
    aliases = {"RED": "R", "GREEN": "G", "BLUE": "B"}
    desc = [aliases.get(d, d) for d in desc]
    idx = []
    for ch in channels:
        key = aliases.get(ch.upper(), ch.upper())
        if key not in desc:
            raise InputError(f"{texture_path}: no band named '{ch}' (bands: {', '.join(desc)}); fix flight.render.channels")
        idx.append(desc.index(key))
    scene = make_scene(dsm, (grid.x0, grid.y0), grid.cell, tex, (tgrid.x0, tgrid.y0), tgrid.cell, desc, block)
    return scene, idx
