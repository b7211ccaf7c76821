"""Moving a block between pycolmap reconstructions and the arrays of :mod:`bundle`."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pycolmap

from kitegully import InputError
from kitegully.georef.bundle import Block
from kitegully.georef.geometry import matrix_to_rotvec, rotvec_to_matrix, triangulate
from kitegully.georef.similarity import Similarity
from kitegully.seeds import rng_for


@dataclass
class ModelIndex:
    """Ids that tie the block's array rows to the reconstruction."""

    image_ids: np.ndarray
    image_names: list[str]
    camera_ids: np.ndarray
    point_ids: np.ndarray
    all_point_ids: np.ndarray
    all_obs_image: np.ndarray
    all_obs_point: np.ndarray
    all_obs_xy: np.ndarray


def intrinsics_of(cam: pycolmap.Camera) -> np.ndarray:
    """``(f, cx, cy, k1, k2)`` of a SIMPLE_RADIAL or RADIAL camera."""
    p = np.asarray(cam.params, float)
    name = cam.model.name
    if name == "SIMPLE_RADIAL":
        return np.array([p[0], p[1], p[2], p[3], 0.0])
    if name == "RADIAL":
        return p[:5].copy()
    if name in ("SIMPLE_PINHOLE",):
        return np.array([p[0], p[1], p[2], 0.0, 0.0])
    raise InputError(f"camera model {name} is not supported by the GCP bundle adjustment (use SIMPLE_RADIAL or RADIAL)")


def select_tie_points(
    obs_image: np.ndarray, obs_point: np.ndarray, obs_xy: np.ndarray, n_points: int, max_tie_points: int,
    image_size: np.ndarray, grid: tuple[int, int] | None, rng: np.random.Generator,
) -> np.ndarray:
    """Indices (sorted) of the tie points kept for the GCP bundle adjustment.

    ``grid = None`` keeps the ``max_tie_points`` longest tracks. With ``grid = (nx, ny)``
    the selection is balanced over the images: each image is cut into ``nx × ny`` cells,
    the points observed in one cell are ranked by track length (longest first, ties by
    the seeded shuffle), and points are taken in order of their best rank in any cell of
    any image, so every cell of every image first gets its best point, then its second,
    and so on (the homogeneous tie-point reduction of photogrammetric practice [I]). Images
    at the strip ends, whose points have short tracks, keep their share. ``image_size`` is
    (n_images, 2) width and height (px). ``max_tie_points = 0`` keeps all.
    O(observations · log observations).

    Parameters
    ----------
    obs_image, obs_point : ndarray (n_obs,) int
        Image row and point index of each observation.
    obs_xy : ndarray (n_obs, 2)
        Pixel of each observation (px).
    n_points : int
        Number of tie points.
    max_tie_points : int
        Most tie points to keep; 0 or less keeps all.
    image_size : ndarray (n_images, 2)
        Width and height of each image (px).
    grid : (int, int) or None
        Cells ``(nx, ny)`` per image; None ranks by track length alone.
    rng : numpy.random.Generator
        Seeded generator that breaks ties.

    Returns
    -------
    ndarray (n_kept,) int
        Sorted indices of the kept tie points.
    """
    if max_tie_points <= 0 or max_tie_points >= n_points:
        return np.arange(n_points)
    track_len = np.bincount(obs_point, minlength=n_points)
    shuffle = rng.random(n_points)
    if grid is None:
        order = np.lexsort((shuffle, -track_len))
        return np.sort(order[:max_tie_points])
    nx, ny = grid
    wh = image_size[obs_image]
    gx = np.clip((obs_xy[:, 0] / wh[:, 0] * nx).astype(int), 0, nx - 1)
    gy = np.clip((obs_xy[:, 1] / wh[:, 1] * ny).astype(int), 0, ny - 1)
    cell = (obs_image * ny + gy) * nx + gx
    o = np.lexsort((shuffle[obs_point], -track_len[obs_point], cell))
    cs = cell[o]
    start = np.r_[0, np.flatnonzero(np.diff(cs)) + 1]
    rank = np.empty(len(o), int)
    rank[o] = np.arange(len(o)) - np.repeat(start, np.diff(np.r_[start, len(o)]))
    best = np.full(n_points, np.iinfo(np.int64).max)
    np.minimum.at(best, obs_point, rank)
    order = np.lexsort((shuffle, -track_len, best))
    return np.sort(order[:max_tie_points])


def block_from_reconstruction(
    rec: pycolmap.Reconstruction, max_tie_points: int, seed: int, tie_grid: tuple[int, int] | None = None,
) -> tuple[Block, ModelIndex]:
    """Arrays of a model with at most ``max_tie_points`` tie points chosen by :func:`select_tie_points`. O(observations).

    Parameters
    ----------
    rec : pycolmap.Reconstruction
        The SfM model; only its registered images are used.
    max_tie_points : int
        Most tie points to keep; 0 keeps all.
    seed : int
        Seed of the generator that breaks ties in the selection.
    tie_grid : (int, int) or None
        Cells ``(nx, ny)`` per image for the balanced selection; None keeps the longest tracks.

    Returns
    -------
    block : Block
        The model's cameras, poses, kept tie points and their observations (no GCPs).
    index : ModelIndex
        Ids that tie the block's rows to ``rec``, with every point and observation of the model.
    """
    image_ids = np.array(sorted(rec.reg_image_ids()), dtype=int)
    img_row = {int(i): k for k, i in enumerate(image_ids)}
    camera_ids = np.array(sorted(rec.cameras.keys()), dtype=int)
    cam_row = {int(c): k for k, c in enumerate(camera_ids)}
    intr = np.array([intrinsics_of(rec.cameras[int(c)]) for c in camera_ids])
    Rs, ts, cam_of = [], [], []
    for i in image_ids:
        img = rec.images[int(i)]
        pose = img.cam_from_world()
        Rs.append(pose.rotation.matrix())
        ts.append(np.asarray(pose.translation))
        cam_of.append(cam_row[int(img.camera_id)])
    pids, xyz, o_img, o_pt, o_xy = [], [], [], [], []
    for k, (pid, p) in enumerate(rec.points3D.items()):
        pids.append(pid)
        xyz.append(p.xyz)
        for el in p.track.elements:
            o_img.append(img_row[int(el.image_id)])
            o_pt.append(k)
            o_xy.append(rec.images[int(el.image_id)].points2D[int(el.point2D_idx)].xy)
    pids = np.array(pids, dtype=np.int64)
    xyz = np.array(xyz, float).reshape(-1, 3)
    o_img, o_pt = np.array(o_img, int), np.array(o_pt, int)
    o_xy = np.array(o_xy, float).reshape(-1, 2)
    size = np.array([[rec.cameras[int(rec.images[int(i)].camera_id)].width, rec.cameras[int(rec.images[int(i)].camera_id)].height]
                     for i in image_ids], float).reshape(-1, 2)
    keep = select_tie_points(o_img, o_pt, o_xy, len(pids), max_tie_points, size, tie_grid, rng_for(seed))
    new_idx = np.full(len(pids), -1)
    new_idx[keep] = np.arange(len(keep))
    sel = new_idx[o_pt] >= 0
    block = Block(
        intr=intr,
        cam_of_image=np.array(cam_of, int),
        rv=matrix_to_rotvec(np.array(Rs)),
        t=np.array(ts, float),
        points=xyz[keep],
        obs_image=o_img[sel],
        obs_point=new_idx[o_pt[sel]],
        obs_xy=o_xy[sel],
    )
    names = [rec.images[int(i)].name for i in image_ids]
    return block, ModelIndex(image_ids, names, camera_ids, pids[keep], pids, o_img, o_pt, o_xy)


def transform_block(block: Block, sim: Similarity) -> Block:
    """The block in the frame ``X' = s R X + t`` (poses re-expressed, points moved)."""
    out = block.copy()
    Rc = rotvec_to_matrix(block.rv)
    Rn = Rc @ sim.R.T
    out.rv = matrix_to_rotvec(Rn)
    out.t = sim.scale * block.t - np.einsum("nij,j->ni", Rn, sim.t)
    out.points = sim.apply(block.points)
    if len(block.gcp_xyz):
        out.gcp_xyz = sim.apply(block.gcp_xyz)
    return out


def retriangulate_all(block: Block, index: ModelIndex) -> tuple[np.ndarray, np.ndarray]:
    """Every tie point of the full model re-intersected with the block's cameras. O(observations)."""
    ci = block.cam_of_image[index.all_obs_image]
    X, miss = triangulate(
        block.intr[ci], block.rv[index.all_obs_image], block.t[index.all_obs_image],
        index.all_obs_xy, index.all_obs_point, len(index.all_point_ids),
    )
    return X, miss


def write_block_to_reconstruction(rec: pycolmap.Reconstruction, block: Block, index: ModelIndex) -> pycolmap.Reconstruction:
    """Copy adjusted poses, intrinsics and re-triangulated points into ``rec`` (in place).

    The model's coordinates are the block's local frame (site CRS minus the block's offset).
    Points whose rays no longer meet (NaN) are deleted.

    Parameters
    ----------
    rec : pycolmap.Reconstruction
        The model to update.
    block : Block
        The adjusted block.
    index : ModelIndex
        Ids that tie the block's rows to ``rec``.

    Returns
    -------
    pycolmap.Reconstruction
        ``rec`` itself, updated.
    """
    for k, c in enumerate(index.camera_ids):
        cam = rec.cameras[int(c)]
        p = np.asarray(cam.params, float).copy()
        p[:3] = block.intr[k, :3]
        p[3] = block.intr[k, 3]
        if cam.model.name == "RADIAL":
            p[4] = block.intr[k, 4]
        cam.params = p
    Rs = rotvec_to_matrix(block.rv)
    for k, i in enumerate(index.image_ids):
        img = rec.images[int(i)]
        pose = pycolmap.Rigid3d(pycolmap.Rotation3d(Rs[k]), block.t[k])
        frame = rec.frames[int(img.frame_id)]
        frame.rig_from_world = pose
    X, _ = retriangulate_all(block, index)
    for k, pid in enumerate(index.all_point_ids):
        if np.all(np.isfinite(X[k])):
            rec.points3D[int(pid)].xyz = X[k]
        else:
            rec.delete_point3D(int(pid))
    return rec
