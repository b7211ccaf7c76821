"""Approximate camera positions from a GPS log, for spatial image matching.

A kite camera carries a 1 Hz GPS logger (Feurer et al. 2018 sect. 2.2.1); interpolated at
each photo's EXIF capture time it gives every image an approximate position (a few metres).
Only images whose positions are close are then matched, instead of all pairs.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pandas as pd
import pycolmap

from kitegully import InputError
from kitegully.sfm.images import ImageInfo
from kitegully.tether.gps import read_track

log = logging.getLogger(__name__)


def positions_from_log(
    infos: list[ImageInfo], log_path: str | Path, crs: str, time_offset_s: float, max_gap_s: float
) -> dict[str, np.ndarray]:
    """Camera positions (site CRS, m) of the images, keyed by their SfM file name.

    Parameters
    ----------
    infos
        Prepared images with EXIF capture times.
    log_path
        GPX or CSV camera log (see :func:`kitegully.tether.gps.read_track`).
    crs
        Site CRS.
    time_offset_s
        Camera clock minus GPS clock (s): a capture at camera time t is at GPS time
        ``t - time_offset_s``.
    max_gap_s
        Images further than this from any fix get no position.

    Raises
    ------
    InputError
        When no image has a capture time inside the log.
    """
    track = read_track(log_path, crs)
    t_log = (track["time"] - track["time"].iloc[0]).dt.total_seconds().to_numpy()
    out: dict[str, np.ndarray] = {}
    for info in infos:
        if not info.capture_time:
            continue
        t = pd.Timestamp(info.capture_time)
        t = (t.tz_localize("UTC") if t.tzinfo is None else t.tz_convert("UTC")) - pd.Timedelta(seconds=time_offset_s)
        ts = (t - track["time"].iloc[0]).total_seconds()
        nearest = np.min(np.abs(t_log - ts))
        if nearest > max_gap_s:
            continue
        out[info.sfm_name] = np.array([np.interp(ts, t_log, track[c].to_numpy()) for c in ("x", "y", "z")])
    if not out:
        raise InputError(
            f"{log_path}: no photo's capture time falls inside the camera GPS log "
            f"(check sfm.matching.log_time_offset_s and the camera clock)"
        )
    log.info("camera GPS log %s: positions for %d of %d images", log_path, len(out), len(infos))
    return out


def write_position_priors(database: str | Path, positions: dict[str, np.ndarray], sigma_m: float) -> int:
    """Write ``positions`` as COLMAP pose priors (Cartesian, centred) into the database.

    Returns the number of priors written.

    Parameters
    ----------
    database : path
        The COLMAP database; its existing pose priors are cleared first.
    positions : mapping
        Camera position (site CRS, m) keyed by image name; the priors are these minus their mean.
    sigma_m : float
        Standard deviation of each position coordinate (m).

    Returns
    -------
    int
        Number of priors written (images of the database with a position).
    """
    centre = np.mean(np.stack(list(positions.values())), axis=0)
    db = pycolmap.Database.open(str(database))
    try:
        db.clear_pose_priors()
        n = 0
        for image in db.read_all_images():
            pos = positions.get(image.name)
            if pos is None:
                continue
            prior = pycolmap.PosePrior()
            prior.corr_data_id = image.data_id
            prior.position = pos - centre
            prior.position_covariance = np.eye(3) * sigma_m**2
            prior.coordinate_system = pycolmap.PosePriorCoordinateSystem.CARTESIAN
            db.write_pose_prior(prior)
            n += 1
    finally:
        db.close()
    return n
