"""The stereo twin's laboratory: the dry box, its frame marks and nails, and the photographs of a pair.

Everything here is a *twin* step (what the world and the rig are): the soil box of Moritani et
al. (2010, sect. 2), 0.30 m along the base by 0.50 m, with 10 printed absolute-orientation marks
on its frame and 20 nails for the point measurement; the rendering of the two photographs of a
height field through the true cameras; the survey of the marks; and the reference surface a point
gauge gives per DEM cell. The processing (:mod:`kitegully.stereo.processing`) never reads it.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Callable, Mapping

import numpy as np

from kitegully.io.raster import GridSpec
from kitegully.stereo.synth import render_heightfield

if TYPE_CHECKING:
    from kitegully.stereo.measure import PrintedMarks
    from kitegully.stereo.rig import StereoRig
    from kitegully.twin.camera import Camera, Pose

#: The dry box (x0, y0, x1, y1), m: 0.30 m along the base (x) by 0.50 m (y).
BOX = (-0.15, -0.25, 0.15, 0.25)
#: Extent of the rendered soil texture (m): the box, its frame and the marks.
TEXTURE_EXTENT = (-0.2, -0.3, 0.2, 0.3)


def relief(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Dry-box soil surface: a few millimetres of clods and rills.

    Parameters
    ----------
    x, y : ndarray
        Positions (m), box centred on (0, 0).

    Returns
    -------
    ndarray
        Elevation (m), within ±6 mm of 0.
    """
    return 0.004 * np.sin(2 * np.pi * x / 0.12) * np.cos(2 * np.pi * y / 0.2) + 0.002 * np.sin(2 * np.pi * (x + y) / 0.05)


def frame_marks(box: tuple[float, float, float, float] = BOX) -> np.ndarray:
    """The 10 absolute-orientation marks on the box frame, 2 cm outside the soil and 1 cm above it.

    Six at the corners and the middle of the long sides, four on the short sides at ±0.2 of the
    box length from its middle (±0.1 m on the 0.5 m box).

    Parameters
    ----------
    box : (x0, y0, x1, y1)
        The soil's extent (m).

    Returns
    -------
    ndarray (10, 3)
        Mark centres (m).
    """
    x0, y0, x1, y1 = box
    yc, dy = 0.5 * (y0 + y1), 0.2 * (y1 - y0)
    return np.array([[x, y, 0.01] for x in (x0 - 0.02, 0.5 * (x0 + x1), x1 + 0.02) for y in (y0 - 0.02, y1 + 0.02)]
                    + [[x0 - 0.02, y, 0.01] for y in (yc - dy, yc + dy)] + [[x1 + 0.02, y, 0.01] for y in (yc - dy, yc + dy)])


def nail_positions(rng: np.random.Generator, box: tuple[float, float, float, float] = BOX, n: int = 20) -> np.ndarray:
    """Nail heads on a 4 × 5 grid in the central part of the box, each jittered by N(0, 5 mm).

    Parameters
    ----------
    rng : numpy.random.Generator
        Source of the jitter.
    box : (x0, y0, x1, y1)
        The soil's extent (m).
    n : int
        Number of nails (at most 20).

    Returns
    -------
    ndarray (n, 2)
        Nail positions x, y (m).
    """
    x0, y0, x1, y1 = box
    xs = np.linspace(x0, x1, 6)[1:-1]
    ys = np.linspace(y0, y1, 7)[1:-1]
    X, Y = np.meshgrid(xs, ys)
    return np.column_stack([X.ravel(), Y.ravel()])[:n] + rng.normal(0, 0.005, (n, 2))


def _window(cam: Camera, pose: Pose, pts: np.ndarray, margin_px: int = 160) -> tuple[int, int, int, int]:
    uv = cam.project(pts, pose)
    return (int(np.nanmin(uv[:, 0])) - margin_px, int(np.nanmin(uv[:, 1])) - margin_px,
            int(np.nanmax(uv[:, 0])) + margin_px, int(np.nanmax(uv[:, 1])) + margin_px)


def render_pair(rig: StereoRig, height: Callable, texture: Any, noise_dn: float, rng: np.random.Generator,
                extent_pts: np.ndarray, marks: PrintedMarks) -> tuple[np.ndarray, np.ndarray]:
    """The two photographs of ``height`` through the rig's true cameras, with the printed frame marks on their plates.

    Only the window of each photograph that sees ``extent_pts`` and the mark plates is rendered.

    Parameters
    ----------
    rig : StereoRig
        True cameras and poses.
    height : callable
        Surface ``z = h(x, y)`` (m).
    texture
        Soil texture (:func:`kitegully.stereo.synth.soil_texture`).
    noise_dn : float
        Image noise (DN of 255).
    rng : numpy.random.Generator
        Source of the image noise.
    extent_pts : ndarray (N, 3)
        Points the rendered window must see (m).
    marks : PrintedMarks
        The frame marks, rendered as printed discs.

    Returns
    -------
    (ndarray, ndarray)
        Left and right photographs (0–255, NaN outside the rendered window).

    Notes
    -----
    Cost: 5 ray–surface iterations per rendered pixel of each window.
    """
    ext = np.vstack([extent_pts, marks.corners()])
    wl = _window(rig.left, rig.pose_left, ext)
    wr = _window(rig.right, rig.pose_right, ext)
    # [I] 5 fixed-point iterations: the ray-surface error shrinks by ~slope·tan(view angle) < 0.1 per iteration
    L = render_heightfield(rig.left, rig.pose_left, height, texture, iterations=5, noise_dn=noise_dn, rng=rng, window=wl, marks=marks)
    R = render_heightfield(rig.right, rig.pose_right, height, texture, iterations=5, noise_dn=noise_dn, rng=rng, window=wr, marks=marks)
    return L, R


def survey_marks(marks_xyz: np.ndarray, rng: np.random.Generator, proc: Mapping[str, Any]) -> np.ndarray:
    """The surveyed coordinates of the frame marks: true + N(0, ``mark_sigma_mm``) per coordinate.

    Parameters
    ----------
    marks_xyz : ndarray (N, 3)
        True mark centres (m).
    rng : numpy.random.Generator
        Source of the survey error.
    proc : mapping
        ``stereo.processing`` (``mark_sigma_mm``).

    Returns
    -------
    ndarray (N, 3)
        Surveyed coordinates (m).
    """
    return marks_xyz + rng.normal(0, proc["mark_sigma_mm"] * 1e-3, marks_xyz.shape)


def box_grid(cell_m: float, box: tuple[float, float, float, float] = BOX, share: float = 0.8) -> GridSpec:
    """DEM grid over the central ``share`` of the box area (the walls shade the rest, paper sect. 2).

    Parameters
    ----------
    cell_m : float
        Cell size (m).
    box : (x0, y0, x1, y1)
        The soil's extent (m).
    share : float
        Share of the box area covered, centred.

    Returns
    -------
    GridSpec
    """
    s = np.sqrt(share)
    nx, ny = int(round((box[2] - box[0]) * s / cell_m)), int(round((box[3] - box[1]) * s / cell_m))
    cx, cy = 0.5 * (box[0] + box[2]), 0.5 * (box[1] + box[3])
    return GridSpec(cx - nx * cell_m / 2, cy + ny * cell_m / 2, cell_m, nx, ny, "EPSG:32632")


def cell_truth(height: Callable, grid: GridSpec, sub: int = 6) -> np.ndarray:
    """Reference surface per cell (mean of ``height`` over ``sub`` × ``sub`` points of the cell), as a point gauge traverse gives.

    Parameters
    ----------
    height : callable
        Surface ``z = h(x, y)`` (m).
    grid : GridSpec
        The DEM grid.
    sub : int
        Samples per cell side.

    Returns
    -------
    ndarray (rows, cols)
        Mean elevation per cell (m).
    """
    X, Y = np.meshgrid(*grid.cell_centres())
    off = (np.arange(sub) + 0.5) / sub - 0.5
    return np.mean([height(X + a * grid.cell, Y + b * grid.cell) for a in off for b in off], axis=0)
