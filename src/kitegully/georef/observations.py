"""A block's GCP observations: the clicks mapped into the SfM frame, triangulated, reprojected.

:func:`collect_observations` turns the GCP file's image names and pixels into block rows and
SfM pixels and sets the observation flags (``missing_images``, ``unregistered``,
``inconsistent_coords``, ``no_obs``, ``single_obs``; see :mod:`kitegully.georef.control`);
the other functions intersect and reproject a GCP in any frame of the block.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from kitegully.georef.bundle import Block
from kitegully.georef.gcp_io import GCP
from kitegully.georef.geometry import project, triangulate, triangulation_covariance
from kitegully.sfm.images import ImageInfo, to_sfm_pixels


@dataclass
class GcpObs:
    """A GCP's usable observations in the block (image rows and SfM pixels) and its flags."""

    gcp: GCP
    rows: np.ndarray
    xy: np.ndarray
    flags: list[str] = field(default_factory=list)




def collect_observations(
    gcps: list[GCP], infos: list[ImageInfo], image_rows: dict[str, int], pixel_frame: str, sfm_frame: str, pixel_scale: float,
    coords_tolerance_m: float, pixel_offset_px: float = 0.0,
) -> list[GcpObs]:
    """Map each GCP's observations into the SfM frame, keeping those in registered images.

    ``image_rows`` maps the prepared image name (``ImageInfo.sfm_name``) to the block row.
    ``pixel_offset_px`` is added to the file's coordinates first: 0.5 when the file puts
    pixel centres at integer coordinates (COLMAP puts the image corner at 0).

    Parameters
    ----------
    gcps : list of GCP
        The GCPs read from the GCP file.
    infos : list of ImageInfo
        The images as the SfM stage prepared them.
    image_rows : dict of str to int
        Prepared image name → block row of the registered images.
    pixel_frame : str
        Frame of the file's pixel coordinates: ``stored`` or ``display``.
    sfm_frame : str
        Pixel frame the SfM worked in (``sfm.image_frame``).
    pixel_scale : float
        File pixels per full-resolution pixel.
    coords_tolerance_m : float
        Largest spread of a GCP's coordinates over its rows before it is flagged
        ``inconsistent_coords`` (m).
    pixel_offset_px : float
        Added to the file's pixel coordinates (px).

    Returns
    -------
    list of GcpObs
        One per GCP, in the order of ``gcps``: block rows, SfM pixels and flags.
    """
    by_name = {i.name: i for i in infos}
    out = []
    for g in gcps:
        rows, xy, missing, unreg = [], [], 0, 0
        for name, px in zip(g.images, g.pixels):
            info = by_name.get(name)
            if info is None:
                missing += 1
                continue
            if info.sfm_name not in image_rows:
                unreg += 1
                continue
            rows.append(image_rows[info.sfm_name])
            xy.append(to_sfm_pixels(px[None] + pixel_offset_px, info, pixel_frame, sfm_frame, pixel_scale)[0])
        flags = []
        if missing:
            flags.append(f"missing_images:{missing}")
        if unreg:
            flags.append(f"unregistered:{unreg}")
        if g.coord_spread_m > coords_tolerance_m:
            flags.append(f"inconsistent_coords:{g.coord_spread_m:.2f}")
        if len(rows) == 0:
            flags.append("no_obs")
        elif len(rows) == 1:
            flags.append("single_obs")
        out.append(GcpObs(g, np.array(rows, int), np.array(xy, float).reshape(-1, 2), flags))
    return out


def triangulated(obs: list[GcpObs], X: np.ndarray) -> np.ndarray:
    """GCPs seen in at least two registered images whose intersection ``X`` is finite (bool, one per GCP)."""
    return np.array([len(o.rows) >= 2 and bool(np.all(np.isfinite(X[k]))) for k, o in enumerate(obs)], dtype=bool)


def triangulate_gcps(block: Block, obs: list[GcpObs]) -> tuple[np.ndarray, np.ndarray]:
    """Each GCP intersected from its rays in the block's frame, and its RMS reprojection error (px)."""
    X = np.full((len(obs), 3), np.nan)
    rp = np.full(len(obs), np.nan)
    for k, o in enumerate(obs):
        if len(o.rows) < 2:
            continue
        ci = block.cam_of_image[o.rows]
        Xk, _ = triangulate(block.intr[ci], block.rv[o.rows], block.t[o.rows], o.xy, np.zeros(len(o.rows), int), 1)
        if not np.all(np.isfinite(Xk)):
            continue
        X[k] = Xk[0]
        p = project(block.intr[ci], block.rv[o.rows], block.t[o.rows], np.repeat(Xk, len(o.rows), 0))
        rp[k] = np.sqrt(np.mean(np.sum((p - o.xy) ** 2, axis=1)))
    return X, rp


def gcp_triangulation_covariance(block: Block, o: GcpObs, X: np.ndarray, sigma_px: float) -> np.ndarray:
    """Covariance (3×3, m²) of the GCP intersected from its observations with ``sigma_px`` click noise.

    Parameters
    ----------
    block : Block
        The block whose cameras observe the GCP.
    o : GcpObs
        The GCP's observations.
    X : ndarray (3,)
        The GCP's position in the block's frame.
    sigma_px : float
        Standard deviation of each pixel coordinate of a click (px).

    Returns
    -------
    ndarray (3, 3)
        Covariance (m²); all NaN where fewer than two rays or the geometry is singular.
    """
    ci = block.cam_of_image[o.rows]
    return triangulation_covariance(block.intr[ci], block.rv[o.rows], block.t[o.rows], X, sigma_px)


def reprojection_of(block: Block, o: GcpObs, X: np.ndarray) -> float:
    """RMS distance (px) between the measured pixels and the projection of ``X``.

    Parameters
    ----------
    block : Block
        The block whose cameras observe the GCP.
    o : GcpObs
        The GCP's observations.
    X : ndarray (3,)
        The point to project, in the block's frame.

    Returns
    -------
    float
        RMS reprojection error (px); NaN when the GCP has no observations.
    """
    if len(o.rows) == 0:
        return float("nan")
    ci = block.cam_of_image[o.rows]
    p = project(block.intr[ci], block.rv[o.rows], block.t[o.rows], np.repeat(X[None], len(o.rows), 0))
    return float(np.sqrt(np.mean(np.sum((p - o.xy) ** 2, axis=1))))


