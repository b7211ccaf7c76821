"""Oriented photos of a close-range SfM model, sphere GCPs triangulated in it, and the similarity to the survey.

The sfm stage's model (pycolmap, self-calibrated RADIAL camera) is read into
:class:`OrientedPhoto` records.  Sphere centres measured in the photos
(:func:`kitegully.closerange.spheres.detect_spheres`) are turned into rays and grouped into
3-D points without knowing which detection belongs to which sphere
(:func:`triangulate_spheres`); the model points are then paired with the surveyed sphere
centres by trying every assignment (:func:`match_markers`), and the model is brought into
the survey frame by a 7-parameter similarity (Umeyama) on them.

Why a similarity and not a GCP bundle: the block of a 10 m scene is internally far more
precise than the sphere survey (tie points reproject to ~0.4 px, ~2.5 mm at 5 m; the RTK
survey scatters 1.5 cm here and ~10 cm effective in 001), so pulling the photos onto the
4 surveyed points in a bundle would bend the self-calibrated block to the survey noise;
the similarity keeps the block's shape and leaves 5 redundant coordinates whose residuals
are the marker error.  PhotoScan (001) put the GCPs in the bundle; with 4 spheres and a
rigid, well-connected ring of views both give the same datum to within the survey noise.

Pixel conventions: COLMAP puts pixel centres at +0.5; :class:`kitegully.twin.camera.Camera`
and the detector at integers.  :func:`read_oriented_photos` converts once.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from kitegully import InputError
from kitegully.georef.similarity import Similarity, umeyama
from kitegully.twin.camera import Camera


@dataclass(frozen=True)
class OrientedPhoto:
    """One registered photo: name, intrinsics (integer pixel centres) and its world→camera pose (model frame)."""

    name: str
    camera: Camera
    R: np.ndarray
    t: np.ndarray

    @property
    def centre(self) -> np.ndarray:
        """Projection centre in the model frame."""
        return -self.R.T @ self.t


def read_oriented_photos(model_dir: str | Path) -> tuple[list[OrientedPhoto], np.ndarray]:
    """Registered photos of a COLMAP model (sorted by name) and its sparse points (N, 3).

    Raises InputError for an unreadable model or a camera model other than (SIMPLE_)RADIAL/PINHOLE.
    """
    import pycolmap

    try:
        rec = pycolmap.Reconstruction(str(model_dir))
    except Exception as exc:  # pycolmap raises plain RuntimeError/ValueError
        raise InputError(f"{model_dir}: cannot read the COLMAP model ({exc})") from None
    photos = []
    for iid in sorted(rec.reg_image_ids(), key=lambda i: rec.images[int(i)].name):
        img = rec.images[int(iid)]
        cam = rec.cameras[int(img.camera_id)]
        p = np.asarray(cam.params, float)
        name = cam.model.name
        if name == "RADIAL":
            f, cx, cy, k1, k2 = p
        elif name == "SIMPLE_RADIAL":
            (f, cx, cy, k1), k2 = p, 0.0
        elif name == "SIMPLE_PINHOLE":
            (f, cx, cy), k1, k2 = p, 0.0, 0.0
        else:
            raise InputError(f"{model_dir}: camera model {name} is not supported (use SIMPLE_RADIAL or RADIAL)")
        camera = Camera(width=int(cam.width), height=int(cam.height), f=float(f), cx=float(cx) - 0.5,
                        cy=float(cy) - 0.5, k1=float(k1), k2=float(k2))
        pose = img.cam_from_world()
        photos.append(OrientedPhoto(img.name, camera, pose.rotation.matrix(), np.asarray(pose.translation, float)))
    pts = np.array([p.xyz for p in rec.points3D.values()], float).reshape(-1, 3)
    return photos, pts


def detection_rays(photo: OrientedPhoto, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Origins and unit directions (model frame) of the rays through image points ``uv`` (px, distorted)."""
    cam = photo.camera
    uv = np.atleast_2d(np.asarray(uv, float))
    xn, yn = cam.undistort((uv[:, 0] - cam.cx) / cam.f, (uv[:, 1] - cam.cy) / cam.f)
    d = np.column_stack([xn, yn, np.ones(len(xn))]) @ photo.R  # camera → model
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return np.repeat(photo.centre[None], len(d), axis=0), d


def _ray_point_distance(O: np.ndarray, D: np.ndarray, X: np.ndarray) -> np.ndarray:
    """(len(X), len(O)) distances of points X from the rays (O, D); points behind a ray count as infinitely far."""
    v = X[:, None, :] - O[None]
    s = np.einsum("pri,ri->pr", v, D)
    dist = np.linalg.norm(v - s[..., None] * D[None], axis=2)
    return np.where(s > 0, dist, np.inf)


def _least_squares_point(O: np.ndarray, D: np.ndarray) -> np.ndarray:
    """Point nearest (least squares) to a bundle of rays."""
    A = np.zeros((3, 3))
    b = np.zeros(3)
    for o, d in zip(O, D):
        P = np.eye(3) - np.outer(d, d)
        A += P
        b += P @ o
    return np.linalg.solve(A, b)


def triangulate_spheres(
    O: np.ndarray, D: np.ndarray, photo_index: np.ndarray, tolerance: float, min_rays: int = 3
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Group detection rays into sphere centres without knowing which sphere each ray sees.

    Candidates are the midpoints of all ray pairs from different photos that pass within
    ``tolerance`` of each other; the candidate that the most rays (from distinct photos) pass
    within ``tolerance`` wins, is re-triangulated from those rays (twice), and its rays are
    removed; repeat while a candidate keeps ``min_rays``.  O(R²) for R rays.

    Parameters
    ----------
    O, D : (R, 3) ray origins and unit directions (model frame).
    photo_index : (R,) photo of each ray.
    tolerance : ray–point distance that still counts as the same sphere (model units).
    min_rays : fewest rays (distinct photos) for a sphere.

    Returns
    -------
    list of (centre (3,), indices of its rays)
    """
    O, D, photo_index = np.asarray(O, float), np.asarray(D, float), np.asarray(photo_index)
    left = np.arange(len(O))
    found = []
    while len(left) >= min_rays:
        i, j = np.triu_indices(len(left), 1)
        i, j = left[i], left[j]
        keep = photo_index[i] != photo_index[j]
        i, j = i[keep], j[keep]
        if len(i) == 0:
            break
        w0 = O[i] - O[j]
        a, b, c = np.einsum("ij,ij->i", D[i], D[i]), np.einsum("ij,ij->i", D[i], D[j]), np.einsum("ij,ij->i", D[j], D[j])
        d, e = np.einsum("ij,ij->i", D[i], w0), np.einsum("ij,ij->i", D[j], w0)
        den = a * c - b * b
        ok = den > 1e-9
        s = np.where(ok, (b * e - c * d) / np.where(ok, den, 1), 0)
        t = np.where(ok, (a * e - b * d) / np.where(ok, den, 1), 0)
        P1, P2 = O[i] + s[:, None] * D[i], O[j] + t[:, None] * D[j]
        good = ok & (s > 0) & (t > 0) & (np.linalg.norm(P1 - P2, axis=1) < tolerance)
        if not good.any():
            break
        cand = 0.5 * (P1[good] + P2[good])
        near = _ray_point_distance(O[left], D[left], cand) < tolerance
        support = np.array([len(np.unique(photo_index[left[row]])) for row in near])
        best = int(np.argmax(support))
        if support[best] < min_rays:
            break
        members = left[near[best]]
        X = cand[best]
        for _ in range(2):
            X = _least_squares_point(O[members], D[members])
            members = left[_ray_point_distance(O[left], D[left], X[None])[0] < tolerance]
        # one ray per photo: the closest
        dist = _ray_point_distance(O[members], D[members], X[None])[0]
        order = np.argsort(dist)
        _, first = np.unique(photo_index[members[order]], return_index=True)
        members = members[order][first]
        if len(members) < min_rays:
            break
        X = _least_squares_point(O[members], D[members])
        found.append((X, members))
        left = np.setdiff1d(left, left[_ray_point_distance(O[left], D[left], X[None])[0] < tolerance])
    return found


def match_markers(
    model_xyz: np.ndarray, survey_xyz: np.ndarray, survey_ids: list[str]
) -> tuple[Similarity, list[int], list[int], np.ndarray]:
    """Pair model sphere centres with surveyed ones and fit the similarity model → survey.

    Every injective assignment of ``min(k, m)`` model points to survey points is tried (at
    most 4! · C(k, 4) for the paper's 4 spheres); the one with the smallest RMS residual of
    its Umeyama similarity wins.

    Returns
    -------
    similarity, the model rows used, the survey row paired with each, and the (n, 3)
    residuals survey − transformed model (m).

    Raises
    ------
    InputError
        Fewer than 3 spheres measured in the model or surveyed.
    """
    k, m = len(model_xyz), len(survey_xyz)
    n = min(k, m)
    if n < 3:
        raise InputError(
            f"only {k} sphere(s) triangulated in the model and {m} surveyed: at least 3 (of {', '.join(survey_ids)}) "
            "must be seen in 3 photos each to georeference the scene"
        )
    best = None
    for rows in itertools.combinations(range(k), n):
        for perm in itertools.permutations(range(m), n):
            a, b = model_xyz[list(rows)], survey_xyz[list(perm)]
            try:
                sim = umeyama(a, b)
            except InputError:
                continue
            res = b - sim.apply(a)
            rms = float(np.sqrt(np.mean(np.sum(res ** 2, axis=1))))
            if best is None or rms < best[0]:
                best = (rms, sim, list(rows), list(perm), res)
    if best is None:
        raise InputError("the triangulated sphere centres are collinear: the similarity to the survey is undetermined")
    _, sim, rows, perm, res = best
    return sim, rows, perm, res
