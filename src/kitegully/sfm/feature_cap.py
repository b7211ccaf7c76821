"""Hold every image to ``sfm.max_num_features`` SIFT keypoints, as the option promises.

COLMAP's CPU SIFT (the VLFeat path that pycolmap runs without a GPU) honours
``max_num_features`` only per difference-of-Gaussians level: it keeps whole levels, from the
coarsest down, until the count *exceeds* the maximum, so the last level kept may hold tens of
thousands of fine-scale keypoints. Measured on the full-size Kamech twin (773 photos,
2000 × 1333 px, ``max_num_features`` 4096, ``first_octave`` 0): median 6 443, 90th
percentile 25 700, maximum 36 330 keypoints per photo, 8.96 M in all, a 1.5 GB database, and
matching and mapping costs that grow with the product of two photos' counts. This module
applies the cap afterwards, as COLMAP intends it: the ``max_num_features`` keypoints of
largest scale (the coarse levels, the most repeatable across the kite's changing altitude
and tilt), orientation duplicates (one location and scale, up to two orientations) counted
once and kept together.
"""

from __future__ import annotations

import logging
import sqlite3
from pathlib import Path

import numpy as np

from kitegully import InputError

log = logging.getLogger(__name__)


def keypoint_scales(keypoints: np.ndarray) -> np.ndarray:
    """Scale (px) of each COLMAP keypoint row.

    Parameters
    ----------
    keypoints : ndarray (N, 6) or (N, 4)
        COLMAP keypoints: ``x, y, a11, a12, a21, a22`` (affine shape; scale = √|det A|) or
        the older ``x, y, scale, orientation``.

    Returns
    -------
    ndarray (N,)
    """
    if keypoints.shape[1] == 6:
        a11, a12, a21, a22 = (keypoints[:, k].astype(np.float64) for k in range(2, 6))
        return np.sqrt(np.abs(a11 * a22 - a12 * a21))
    if keypoints.shape[1] == 4:
        return keypoints[:, 2].astype(np.float64)
    raise ValueError(f"COLMAP keypoints have 4 or 6 columns, not {keypoints.shape[1]}")


def select_largest(keypoints: np.ndarray, max_num_features: int) -> np.ndarray:
    """Indices (ascending) of the rows kept: the ``max_num_features`` largest-scale locations.

    Rows sharing one location (orientation duplicates) count as one feature and are kept
    or dropped together; ties in scale keep the earlier location. O(N log N).

    Parameters
    ----------
    keypoints : ndarray (N, 6) or (N, 4)
    max_num_features : int
        At least 1.

    Returns
    -------
    ndarray of int
        All rows when the image has at most ``max_num_features`` distinct locations.
    """
    n = len(keypoints)
    if n == 0:
        return np.arange(0)
    scale = keypoint_scales(keypoints)
    # one location = one feature (its orientations' affine shapes give the same scale up to float32 rounding)
    _, first, group = np.unique(keypoints[:, :2], axis=0, return_index=True, return_inverse=True)
    group = group.ravel()
    if len(first) <= max_num_features:
        return np.arange(n)
    group_scale = np.zeros(len(first))
    np.maximum.at(group_scale, group, scale)
    # largest scale first; equal scales in their order of appearance
    order = np.lexsort((first, -group_scale))
    keep_group = np.zeros(len(first), dtype=bool)
    keep_group[order[:max_num_features]] = True
    return np.flatnonzero(keep_group[group])


def cap_features(database: Path | str, max_num_features: int) -> dict[str, int]:
    """Cut every image's keypoints and descriptors in a COLMAP database to the cap, in place.

    Run after feature extraction and before matching (matches index keypoint rows).

    Parameters
    ----------
    database : path
        COLMAP SQLite database with ``keypoints`` and ``descriptors`` tables.
    max_num_features : int
        Distinct keypoint locations kept per image (orientation duplicates come along).

    Returns
    -------
    dict
        ``images``, ``images_capped``, ``keypoints_before``, ``keypoints_after``,
        ``max_before`` (the largest count of one image before).

    Notes
    -----
    O(total keypoints · log); one image's rows in memory at a time.
    """
    if max_num_features < 1:
        raise InputError(f"sfm.max_num_features must be at least 1, not {max_num_features}")
    stats = dict(images=0, images_capped=0, keypoints_before=0, keypoints_after=0, max_before=0)
    con = sqlite3.connect(str(database))
    try:
        ids = [r[0] for r in con.execute("SELECT image_id FROM keypoints ORDER BY image_id")]
        for image_id in ids:
            rows, cols, blob = con.execute("SELECT rows, cols, data FROM keypoints WHERE image_id = ?", (image_id,)).fetchone()
            stats["images"] += 1
            stats["keypoints_before"] += rows
            stats["max_before"] = max(stats["max_before"], rows)
            if rows == 0:
                continue
            if len(blob) != rows * cols * 4:
                raise InputError(f"{database}: image {image_id}'s keypoints are not {rows} x {cols} float32 values")
            kp = np.frombuffer(blob, dtype=np.float32).reshape(rows, cols)
            keep = select_largest(kp, max_num_features)
            stats["keypoints_after"] += len(keep)
            if len(keep) == rows:
                continue
            drow = con.execute("SELECT rows, cols, data FROM descriptors WHERE image_id = ?", (image_id,)).fetchone()
            if drow is None or drow[0] != rows:
                raise InputError(f"{database}: image {image_id} has {rows} keypoints but "
                                 f"{'no' if drow is None else drow[0]} descriptors")
            if len(drow[2]) != drow[0] * drow[1]:
                raise InputError(f"{database}: image {image_id}'s descriptors are not {drow[0]} x {drow[1]} bytes (SIFT)")
            desc = np.frombuffer(drow[2], dtype=np.uint8).reshape(drow[0], drow[1])
            con.execute("UPDATE keypoints SET rows = ?, data = ? WHERE image_id = ?",
                        (len(keep), np.ascontiguousarray(kp[keep]).tobytes(), image_id))
            con.execute("UPDATE descriptors SET rows = ?, data = ? WHERE image_id = ?",
                        (len(keep), np.ascontiguousarray(desc[keep]).tobytes(), image_id))
            stats["images_capped"] += 1
        con.commit()
    finally:
        con.close()
    if stats["images_capped"]:
        log.info("features capped to %d locations on %d of %d images (COLMAP's CPU SIFT keeps whole scale levels): "
                 "%d -> %d keypoints, the largest image had %d", max_num_features, stats["images_capped"], stats["images"],
                 stats["keypoints_before"], stats["keypoints_after"], stats["max_before"])
    return stats
