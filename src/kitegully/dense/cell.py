"""DSM cell size from the measured ground sampling distance (``dense.cell_m: auto``).

The ground sampling distance (GSD) is measured on the oriented model itself, not taken
from a flight plan: for every image, the tie points it sees (those that project inside
its frame, in front of it) give the depth of the ground along its optical axis, and
``GSD = depth / f`` with ``f`` the self-calibrated focal length in pixels of the images
the matcher reads. The block's GSD is the median over images, so a few oblique or
high frames do not move it.

``auto`` then takes a cell of 2 GSD [I]: an object-space matcher cannot resolve a surface
finer than about two image pixels (its correlation windows need texture from several
pixels per cell), and the paper's 0.2 m cell over ~0.1 m photos is the same ratio [P].
The value is rounded to one significant digit (step 10^⌊log10(2·GSD)⌋: 0.01 m for cells
of 1–9 cm, 0.1 m for 0.1–0.9 m, 1 m above), so cells are round numbers that align with
other grids of the same cell. The matching window is set in cells
(``dense.matching.window_half_cells``), so it scales with the cell: its ground size is
``(2h + 1) · cell`` and in the images about ``(2h + 1) · cell / GSD`` pixels whatever
the GSD; both are logged.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from kitegully import InputError
from kitegully.dense.views import ViewSet

log = logging.getLogger(__name__)

#: cell size in GSD of ``cell_m: auto`` [I] (and [P]: 0.2 m cell over ~0.1 m photos)
AUTO_CELL_GSD = 2.0


@dataclass(frozen=True)
class CellChoice:
    """The DSM cell and how it was chosen.

    Attributes
    ----------
    cell_m : float
        DSM cell (m).
    gsd_m : float
        Measured GSD of the images the matcher reads (median over images, m).
    auto : bool
        True when ``dense.cell_m`` was ``auto``.
    window_m : float
        Ground side of the correlation window, ``(2h + 1) · cell_m`` (m).
    window_px : float
        The same window in image pixels, ``window_m / gsd_m``.
    """

    cell_m: float
    gsd_m: float
    auto: bool
    window_m: float
    window_px: float


def measured_gsd(views: ViewSet, min_points: int = 5) -> float:
    """Median ground sampling distance (m) of the oriented images, from their tie points.

    Parameters
    ----------
    views
        Oriented images (self-calibrated focal length ``f`` in px) and the model's tie
        points in the same local metric frame.
    min_points
        Tie points an image needs in its frame to take part.

    Returns
    -------
    float
        Median over images of (median depth of the tie points in the frame) / f.

    Cost: O(V · N) for V images and N tie points.
    """
    P = views.sparse_points
    if len(P) < min_points:
        raise InputError(f"dense.cell_m is auto but the model has {len(P)} tie points; give dense.cell_m in metres")
    gsds = []
    for v in views.images:
        u, w, depth = v.project(P)
        inside = (depth > 0) & (u >= 0) & (u < v.width) & (w >= 0) & (w < v.height)
        if inside.sum() >= min_points:
            gsds.append(float(np.median(depth[inside])) / v.f)
    if not gsds:
        raise InputError("dense.cell_m is auto but no image sees enough tie points to measure its GSD; give dense.cell_m in metres")
    return float(np.median(gsds))


def round_cell(x: float) -> float:
    """``x`` rounded to one significant digit, halves up (0.54 → 0.5, 0.046 → 0.05, 0.15 → 0.2, 2.6 → 3)."""
    if not (x > 0 and math.isfinite(x)):
        raise ValueError(f"cell size must be a positive number, got {x}")
    step = 10.0 ** math.floor(math.log10(x))
    return round(math.floor(x / step + 0.5 + 1e-9) * step, 10)  # 1e-9: 0.15 / 0.1 is 1.4999...


def choose_cell(cell_cfg: Any, views: ViewSet, window_half_cells: int) -> CellChoice:
    """The DSM cell: ``dense.cell_m`` in metres, or ``auto`` = 2 × measured GSD rounded.

    Parameters
    ----------
    cell_cfg
        ``dense.cell_m``: a number of metres (used unchanged) or ``"auto"``.
    views
        Oriented images and tie points (see :func:`measured_gsd`).
    window_half_cells
        ``dense.matching.window_half_cells``, for the logged window size.

    Returns
    -------
    CellChoice
        The cell, the measured GSD (NaN when an explicit cell is given and the model has
        too few tie points to measure it) and the window's ground and image size.
    """
    auto = cell_cfg == "auto"
    if auto:
        gsd = measured_gsd(views)
        cell = round_cell(AUTO_CELL_GSD * gsd)
    else:
        cell = float(cell_cfg)
        try:
            gsd = measured_gsd(views)
        except InputError:  # an explicit cell needs no GSD; it is only reported
            gsd = float("nan")
    win_m = (2 * int(window_half_cells) + 1) * cell
    choice = CellChoice(cell, gsd, auto, win_m, win_m / gsd)
    if auto:
        log.info("dense.cell_m auto: measured GSD %.4f m (median of %d images) -> 2 x GSD = %.4f m -> cell %g m",
                 gsd, len(views.images), AUTO_CELL_GSD * gsd, cell)
    else:
        log.info("dense.cell_m %g m given (%.2f x the measured GSD %.4f m)", cell, cell / gsd, gsd)
    log.info("matching window %d x %d cells = %.3f m on the ground, about %.1f image pixels",
             2 * window_half_cells + 1, 2 * window_half_cells + 1, win_m, choice.window_px)
    return choice
