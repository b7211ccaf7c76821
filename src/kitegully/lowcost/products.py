"""The survey's rasters from the georeferenced block: the tie points' TIN DSM and white-balanced reflectance.

Paper 004 sect. 2.5: a DSM from a Delaunay TIN, and mosaics turned into reflectance with the
Spectralon panel shot at the same camera settings.
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np
from scipy.interpolate import LinearNDInterpolator

from kitegully.dense.views import ViewSet
from kitegully.io.raster import GridSpec

if TYPE_CHECKING:
    from kitegully.georef.similarity import Similarity


def views_in_site_crs(views: ViewSet, sim: Similarity, offset: np.ndarray) -> ViewSet:
    """Views and tie points of the model in the site CRS: ``X_world = s R X_model + t``, less ``offset``.

    Parameters
    ----------
    views : ViewSet
        Views of the SfM model (model frame).
    sim : Similarity
        Model-to-site similarity.
    offset : ndarray (3,)
        Local offset subtracted from every site coordinate.

    Returns
    -------
    ViewSet
        Rotated, moved views and tie points with ``offset``.
    """
    imgs = [replace(im, R=im.R @ sim.R.T, C=sim.apply(im.C) - offset) for im in views.images]
    return ViewSet(imgs, offset, sim.apply(views.sparse_points) - offset)


def tin_dsm(points: np.ndarray, cell: float, crs: str) -> tuple[np.ndarray, GridSpec]:
    """DSM sampled from the 2-D Delaunay TIN of ``points`` (x, y, z) at ``cell`` (paper 004
    sect. 2.5, [I] Delaunay on x, y); NaN outside the hull. O(n log n + cells).

    Parameters
    ----------
    points : ndarray (n, 3)
        Points x, y, z in the site CRS (m).
    cell : float
        DSM cell size (m).
    crs : str
        Site CRS.

    Returns
    -------
    dsm : ndarray (H, W) float32
        Heights (m) of the TIN at the cell centres.
    grid : GridSpec
        Grid covering the 0.5–99.5 percentile range of the points' x and y.
    """
    lo = np.percentile(points[:, :2], 0.5, axis=0)
    hi = np.percentile(points[:, :2], 99.5, axis=0)
    grid = GridSpec.covering((lo[0], lo[1], hi[0], hi[1]), cell, crs)
    xs, ys = np.meshgrid(*grid.cell_centres())
    o = points[:, :2].mean(axis=0)
    f = LinearNDInterpolator(points[:, :2] - o, points[:, 2])
    return f(xs - o[0], ys - o[1]).astype(np.float32), grid


def white_balance(dn: np.ndarray, panel_dn: np.ndarray, panel_reflectance: float, gamma: float) -> np.ndarray:
    """Reflectance of each channel: linearised DN over the linearised Spectralon DN shot at
    the same settings, times the panel's reflectance; DN 0 (no data) becomes NaN.

    Parameters
    ----------
    dn : ndarray (B, H, W) uint8
        Mosaic digital numbers, 0 = no data.
    panel_dn : ndarray (B,)
        Mean DN of the Spectralon panel in each channel.
    panel_reflectance : float
        Reflectance of the panel (0–1).
    gamma : float
        Tone curve exponent of the JPEGs, ``DN = 255 signal^(1/gamma)``.

    Returns
    -------
    ndarray (B, H, W) float32
        Reflectance of each channel, NaN where ``dn`` is 0.
    """
    lin = (dn.astype(np.float32) / 255.0) ** gamma
    ref = (np.asarray(panel_dn, np.float32) / 255.0) ** gamma
    out = lin / ref.reshape(-1, *([1] * (dn.ndim - 1))) * panel_reflectance
    out[dn == 0] = np.nan
    return out.astype(np.float32)
