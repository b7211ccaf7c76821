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
from typing import Callable

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


def verify_spheres(
    found: list[tuple[np.ndarray, np.ndarray]], O: np.ndarray, alpha: np.ndarray, points: np.ndarray,
    max_radius_spread: float = 0.15, ground_reach: float = 6.0, min_ground_points: int = 6,
) -> list[dict]:
    """Test triangulated sphere candidates with what a sphere is in 3-D; one record per candidate.

    * **Radius.** Each ray of a candidate saw the sphere under the angular radius ``alpha``;
      at its distance ``D`` from the centre that is a radius ``D·sin(alpha)`` in model units.
      A sphere gives the same radius from every side (their median is ``radius``; their
      median relative deviation ``radius_spread`` must stay within ``max_radius_spread``);
      a flat bright patch on the ground seen from different sides and distances does not.
    * **Above the ground** (reported, not decisive). A sphere resting on the ground has its
      centre one radius above it: the tie points (``points``) within ``ground_reach`` radii
      of the centre (those within 1.5 radii left out) give a least-squares plane and the
      centre's distance from it is ``height`` (NaN with fewer than ``min_ground_points``).
      Measured in scene 05: 0.5–1.1 radii for the spheres, but 0–1 of their own radius
      for the false candidates too (small white clods), so it does not separate them.

    Parameters
    ----------
    found : :func:`triangulate_spheres` output (centre, ray indices).
    O : (R, 3) ray origins; alpha : (R,) angular radius of each ray's detection (rad).
    points : (N, 3) tie points of the model.
    max_radius_spread : relative tolerance. [I] a 6 px image radius measured to ~0.3 px is
        5 %: 3σ is 15 %.
    ground_reach : radii around the centre that count as its ground. min_ground_points : fewest for a plane.

    Returns
    -------
    list of dict: ``radius, radius_spread, height, n_ground_points, sphere`` (bool) per candidate.

    Notes
    -----
    O(K · N) for K candidates and N tie points.
    """
    out = []
    pts = np.asarray(points, float).reshape(-1, 3)
    for X, members in found:
        D = np.linalg.norm(O[members] - X, axis=1)
        r_i = D * np.sin(np.asarray(alpha)[members])
        r = float(np.median(r_i))
        spread = float(np.median(np.abs(r_i - r)) / r) if r > 0 else np.inf
        d = np.linalg.norm(pts - X, axis=1)
        g = pts[(d > 1.5 * r) & (d < ground_reach * r)]
        height = np.nan
        if len(g) >= min_ground_points:
            c = g.mean(axis=0)
            normal = np.linalg.svd(g - c, full_matrices=False)[2][-1]
            height = float(abs((X - c) @ normal))
        ok = spread <= max_radius_spread
        out.append({"radius": r, "radius_spread": spread, "height": height, "n_ground_points": int(len(g)), "sphere": bool(ok)})
    return out


def _pairwise(X: np.ndarray) -> np.ndarray:
    return np.linalg.norm(X[:, None] - X[None], axis=2)


def match_markers(
    model_xyz: np.ndarray, survey_xyz: np.ndarray, survey_ids: list[str], budget_m: float = 0.10, max_candidates: int = 12,
    plausible: Callable[[Similarity], bool] | None = None, radii: np.ndarray | None = None, radius_m: float = 0.10,
    radius_tolerance: float = 0.25,
) -> tuple[Similarity, list[int], list[int], np.ndarray]:
    """Pair model sphere centres with surveyed ones and fit the similarity model → survey (robust, with a plausibility check).

    The triangulated candidates may hold false spheres (a white stone seen in 3 photos, a
    sphere split in two by a biased detection), so the best-RMS assignment of all
    candidates can pair the wrong ones (scene 03: 0.51 m).  Hypothesise and verify instead:

    1. every ordered triple of candidates × every triple of surveyed spheres; the triple is
       kept only if its three distances agree with the surveyed ones up to one scale within
       ``2 · budget_m`` (rotation-free check: two points each within the budget);
    2. its Umeyama similarity maps all candidates into the survey frame; surveyed spheres
       with a mapped candidate within ``budget_m`` (one-to-one, Hungarian) are the inliers;
    3. the hypothesis with the most inliers wins (ties: the smaller RMS of the similarity
       refitted on its inliers); it is accepted only if it pairs >= 3 spheres, every
       refitted residual is within ``budget_m`` and ``plausible(similarity)`` holds (the
       stage checks that the cameras come out at the pole's height above the ground);
       otherwise the next hypothesis is tried;
    4. it must be unique: a second plausible assignment with as many inliers (false white
       blobs among many candidates fit 3 spheres by chance: 2 redundant coordinates only)
       makes the pairing ambiguous and the scene is rejected, unless it places the paired
       spheres within the budget of the first (a sphere triangulated twice: the same datum).

    The budget must be the survey's real accuracy: with 10 cm instead of the twin's 5 cm
    (3.4 σ of its 1.5 cm survey), scene 05's 22 false candidates gave a unique, plausible
    3-sphere chance fit 6 m off (residuals 2–9.5 cm).

    With ``radii`` (each candidate's radius in model units, :func:`verify_spheres`) a
    candidate can pair only with a similarity whose scale makes it a sphere of ``radius_m``
    within ``radius_tolerance`` (relative): a false white patch fits the survey's geometry
    by chance but not also the spheres' size. [I] 25 %: image radii of 5–25 px measured
    to ~0.3 px (≤ 6 %) and their spread over the photos (≤ 15 %).

    ``budget_m`` is the survey's accuracy ([P] RTK ±10 cm effective in 001).  The first
    ``max_candidates`` candidates (in the order given: most rays first) are used.
    Cost: O(C(k,3) · m!/(m−3)! · k·m) for k candidates and m surveyed spheres
    (8 candidates, 4 spheres: ~1 300 hypotheses, milliseconds).

    Parameters
    ----------
    model_xyz : ndarray (k, 3)
        Triangulated sphere centres (model frame), most rays first.
    survey_xyz : ndarray (m, 3)
        Surveyed sphere centres (m).
    survey_ids : list of str
        Names of the surveyed spheres, for the error messages.
    budget_m : float
        Survey accuracy (m): largest residual of a paired sphere.
    max_candidates : int
        Number of model candidates used.
    plausible : callable or None
        Check of a similarity; None accepts every one.
    radii : ndarray (k,) or None
        Radius of each candidate (model units); None skips the size check.
    radius_m : float
        Surveyed sphere radius (m).
    radius_tolerance : float
        Relative tolerance on the scaled candidate radius.

    Returns
    -------
    similarity, the model rows used, the survey row paired with each, and the (n, 3)
    residuals survey − transformed model (m).

    Raises
    ------
    InputError
        Fewer than 3 spheres measured in the model or surveyed, or no assignment within the budget.
    """
    from scipy.optimize import linear_sum_assignment

    model_xyz = np.asarray(model_xyz, float).reshape(-1, 3)[:max_candidates]
    rad = None if radii is None else np.asarray(radii, float)[:max_candidates]

    def sized(sim_: Similarity, rows_) -> np.ndarray:
        if rad is None:
            return np.ones(len(rows_), dtype=bool)
        return np.abs(sim_.scale * rad[rows_] - radius_m) <= radius_tolerance * radius_m
    survey_xyz = np.asarray(survey_xyz, float).reshape(-1, 3)
    k, m = len(model_xyz), len(survey_xyz)
    if min(k, m) < 3:
        raise InputError(
            f"only {k} sphere(s) triangulated in the model and {m} surveyed: at least 3 (of {', '.join(survey_ids)}) "
            "must be seen in 3 photos each to georeference the scene"
        )
    dm, ds = _pairwise(model_xyz), _pairwise(survey_xyz)
    need = 3
    hyps, worst_seen = {}, np.inf
    for rows in itertools.combinations(range(k), 3):
        r = list(rows)
        d = dm[np.ix_(r, r)][np.triu_indices(3, 1)]
        for perm in itertools.permutations(range(m), 3):
            p = list(perm)
            D = ds[np.ix_(p, p)][np.triu_indices(3, 1)]
            scale = float(d @ D / max(d @ d, 1e-300))
            if np.abs(scale * d - D).max() > 2 * budget_m:
                continue
            try:
                sim = umeyama(model_xyz[r], survey_xyz[p])
            except InputError:
                continue
            if not sized(sim, r).all():
                continue
            cost = np.linalg.norm(survey_xyz[:, None] - sim.apply(model_xyz)[None], axis=2)  # (m, k)
            cost[:, ~sized(sim, np.arange(k))] = 1e9  # not a sphere of the surveyed size at this scale
            si, mi = linear_sum_assignment(cost)
            ok = cost[si, mi] <= budget_m
            si, mi = si[ok], mi[ok]
            if len(si) < need:
                continue
            try:
                sim2 = umeyama(model_xyz[mi], survey_xyz[si])
            except InputError:
                continue
            if not sized(sim2, mi).all():
                continue
            res = survey_xyz[si] - sim2.apply(model_xyz[mi])
            rms = float(np.sqrt(np.mean(np.sum(res ** 2, axis=1))))
            worst_seen = min(worst_seen, float(np.linalg.norm(res, axis=1).max()))
            pairs = tuple(sorted(zip(mi.tolist(), si.tolist())))
            if np.linalg.norm(res, axis=1).max() <= budget_m and pairs not in hyps:
                hyps[pairs] = ((-len(si), rms), (sim2, [int(x) for x in mi], [int(x) for x in si], res))
    best, best_key, n_implausible, rivals = None, None, 0, 0
    for key, h in sorted(hyps.values(), key=lambda kv: kv[0]):
        if best is not None and key[0] > best_key[0]:
            break
        if plausible is None or plausible(h[0]):
            if best is None:
                best, best_key = h, key
            elif np.abs(h[0].apply(model_xyz[best[1]]) - best[0].apply(model_xyz[best[1]])).max() > budget_m:
                rivals += 1  # another assignment with as many spheres fits as well and moves the model
            # (a sphere triangulated twice, its two copies within the budget, is no rival)
        elif best is None:
            n_implausible += 1
    if best is not None and rivals:
        raise InputError(
            f"{rivals + 1} different assignments of the {k} triangulated sphere(s) to the {m} surveyed ({', '.join(survey_ids)}) "
            f"fit {-best_key[0]} spheres each within the survey budget of {budget_m:.2f} m: the pairing is ambiguous "
            "(false white blobs among the candidates), the scene is not georeferenced"
        )
    if best is None and n_implausible:
        raise InputError(
            f"the {n_implausible} assignment(s) of the {k} triangulated sphere(s) to the {m} surveyed ({', '.join(survey_ids)}) "
            f"within the survey budget of {budget_m:.2f} m put the cameras where they cannot have been: the spheres were not "
            "measured (false white blobs fit by chance)"
        )
    if best is None:
        extra = "" if not np.isfinite(worst_seen) else f" (best assignment: largest residual {worst_seen:.3f} m)"
        raise InputError(
            f"no assignment of {need} of the {k} triangulated sphere(s) to the {m} surveyed ({', '.join(survey_ids)}) fits the "
            f"similarity within the survey budget of {budget_m:.2f} m{extra}: the spheres are mis-measured or not all were found"
        )
    return best
