"""Georeferencing a pole-camera model on the white marker spheres (001 sect. 2.2).

The spheres are detected in every oriented photo (:mod:`.spheres`), their rays intersected
and checked to be round from every side (:mod:`.model`), paired with the surveyed centres
and a similarity fitted, kept only where it puts the cameras at the pole's height.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import TYPE_CHECKING, Mapping, Sequence

import numpy as np
import pandas as pd

from kitegully import InputError
from kitegully.closerange.model import detection_rays, match_markers, triangulate_spheres, verify_spheres
from kitegully.closerange.spheres import detect_spheres
from kitegully.georef.similarity import Similarity

if TYPE_CHECKING:
    from kitegully.closerange.stage import CloseRangeParams

log = logging.getLogger(__name__)


@dataclass
class SphereGeoreference:
    """The similarity model → survey from the marker spheres found in the oriented photos.

    Attributes
    ----------
    sim : Similarity
        Model → site coordinates.
    found_all, found : list
        Triangulated sphere candidates, and those that passed :func:`verify_spheres` (one radius from
        every side), each ``(xyz, photo indices, ...)``.
    checks : list of dict
        The verification of each kept candidate (``radius``, ``height`` in model units).
    rows, perm : sequence of int
        Kept candidates paired with the survey (indices into ``found``) and their survey rows.
    res : ndarray (n, 3)
        Residuals of the paired spheres after the similarity (m).
    ids : list of str
        Survey ids (``gcp_id``).
    detections : list of (str, float, float)
        Every sphere detection (photo, u, v).
    centres : ndarray (n_photos, 3)
        Camera centres in the model.
    """

    sim: Similarity
    found_all: list
    found: list
    checks: list
    rows: Sequence[int]
    perm: Sequence[int]
    res: np.ndarray
    ids: list
    detections: list
    centres: np.ndarray


def georeference_on_spheres(photos: Sequence, images: Mapping[str, np.ndarray], sparse: np.ndarray, survey: pd.DataFrame,
                            params: "CloseRangeParams", source: str, scene: str) -> SphereGeoreference:
    """Detect the white marker spheres in the oriented photos, triangulate them and fit the similarity to the survey.

    Parameters
    ----------
    photos : sequence
        Oriented photos (:func:`read_oriented_photos`).
    images : mapping
        The photographs SfM saw, by name.
    sparse : ndarray (n, 3)
        Tie points of the model (the spheres stand above them).
    survey : DataFrame
        Surveyed sphere centres: ``gcp_id, x, y, z``.
    params : CloseRangeParams
    source, scene : str
        Named in messages and the log.

    Returns
    -------
    SphereGeoreference

    Notes
    -----
    Cost: the sphere detector over every photo, O(pixels); triangulation and pairing are small.
    """
    O, D, pid, alpha, det_rows = [], [], [], [], []
    for k, ph in enumerate(photos):
        det = detect_spheres(images[ph.name], ph.camera, params.spheres)
        if len(det):
            o, d = detection_rays(ph, det[["u_px", "v_px"]].to_numpy())
            O.append(o)
            D.append(d)
            pid += [k] * len(det)
            alpha += det["alpha_rad"].tolist()
            det_rows += [(ph.name, u, v) for u, v in det[["u_px", "v_px"]].to_numpy()]
    if not O:
        raise InputError(f"{source}: no white sphere was found in any of the {len(photos)} oriented photos")
    O, D, pid, alpha = np.concatenate(O), np.concatenate(D), np.array(pid), np.array(alpha)
    centres = np.array([p.centre for p in photos])
    ring = float(np.median(np.linalg.norm(centres - centres.mean(axis=0), axis=1)))
    tol = params.sphere_tolerance_m * ring / 5.0 if ring > 0 else params.sphere_tolerance_m
    # the model's scale is arbitrary: express the tolerance via the ring radius (~5 m at the walk's size)
    found_all = triangulate_spheres(O, D, pid, tol)
    checks_all = verify_spheres(found_all, O, alpha, sparse)
    found = [f for f, c in zip(found_all, checks_all) if c["sphere"]]
    checks = [c for c in checks_all if c["sphere"]]
    log.info("%s: %d sphere detections in %d photos, %d triangulated, %d with one radius from every side (radius spread <= 15 %%)",
             scene, len(O), len(photos), len(found_all), len(found))
    model_xyz = np.array([f[0] for f in found]).reshape(-1, 3)
    radii = np.array([c["radius"] for c in checks])
    sxyz = survey[["x", "y", "z"]].to_numpy(float)
    ids = survey["gcp_id"].astype(str).tolist()
    # plausibility: with the similarity the cameras stand at the pole's height above the
    # ground, here the plane through the surveyed spheres lowered by their radius (a scale or
    # an orientation from false candidates puts them metres too high, or under the ground)
    A = np.column_stack([sxyz[:, 0] - sxyz[:, 0].mean(), sxyz[:, 1] - sxyz[:, 1].mean(), np.ones(len(sxyz))])
    plane = np.linalg.lstsq(A, sxyz[:, 2], rcond=None)[0]

    def cameras_on_poles(sim_) -> bool:
        c = sim_.apply(centres)
        ground = plane[0] * (c[:, 0] - sxyz[:, 0].mean()) + plane[1] * (c[:, 1] - sxyz[:, 1].mean()) + plane[2] - params.sphere_radius_m
        h = float(np.median(c[:, 2] - ground))
        return 0.5 * params.pole_height_m <= h <= 2.0 * params.pole_height_m

    sim, rows, perm, res = match_markers(model_xyz, sxyz, ids, params.marker_budget_m, plausible=cameras_on_poles,
                                         radii=radii, radius_m=params.sphere_radius_m)
    return SphereGeoreference(sim, found_all, found, checks, rows, perm, res, ids, det_rows, centres)
