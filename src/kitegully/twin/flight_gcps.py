"""GCP targets in the simulated photos: true pixel positions and what a person digitises.

Pixel coordinates use the convention of :mod:`kitegully.twin.camera` and OpenDroneMap /
OpenSfM: the centre of the top-left pixel is (0, 0), x to the right, y down.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from kitegully import InputError
from kitegully.twin.camera import Camera
from kitegully.twin.flight import pose_from_row
from kitegully.twin.render import Scene, surface_height, visible


def target_pixels(
    camera: Camera,
    poses: pd.DataFrame,
    targets: pd.DataFrame,
    scene: Scene,
    edge_margin_px: float,
    occlusion_tolerance_m: float,
) -> pd.DataFrame:
    """True pixel position of every target in every image it projects into.

    A target counts as ``fully_in_view`` when its centre and the four corners of its
    square (``size_m``, axis-aligned, corners on the surface) project inside the image,
    ``edge_margin_px`` away from the border, and none of those five points is hidden by
    the surface (ray cast, ``occlusion_tolerance_m``). Cost: O(images × targets) rays.

    Returns columns ``image, gcp_id, im_x_px, im_y_px, fully_in_view, distance_m``.

    Parameters
    ----------
    camera : Camera
        The camera.
    poses : DataFrame
        One row per image (``poses.csv``: ``image`` and the pose columns of
        :func:`kitegully.twin.flight.pose_from_row`).
    targets : DataFrame
        True targets: ``gcp_id``, ``x``, ``y``, ``z`` (m) and ``size_m``.
    scene : Scene
        The surface, for corner heights and occlusion.
    edge_margin_px : float
        Least distance of the five points from the image border (px).
    occlusion_tolerance_m : float
        Tolerance of the visibility test (m), see :func:`kitegully.twin.render.visible`.

    Returns
    -------
    DataFrame
        One row per image and target whose centre projects into the image or within half a pixel of it.
    """
    rows = []
    centres = targets[["x", "y", "z"]].to_numpy(float)
    half = targets["size_m"].to_numpy(float) / 2.0
    offs = np.array([[0, 0], [-1, -1], [-1, 1], [1, -1], [1, 1]], dtype=float)
    for _, p in poses.iterrows():
        pose = pose_from_row(p)
        uv = camera.project(centres, pose)
        near = camera.in_image(np.nan_to_num(uv, nan=-1e9), -0.5)
        for i in np.flatnonzero(near):
            px, py = centres[i, 0] + offs[:, 0] * half[i], centres[i, 1] + offs[:, 1] * half[i]
            pz = surface_height(scene, px, py)
            pz[0] = centres[i, 2]
            pts = np.column_stack([px, py, np.where(np.isfinite(pz), pz, centres[i, 2])])
            puv = camera.project(pts, pose)
            inside = bool(np.all(camera.in_image(np.nan_to_num(puv, nan=-1e9), edge_margin_px)))
            seen = bool(np.all(visible(scene, pose, pts, occlusion_tolerance_m))) if inside else False
            rows.append(
                dict(
                    image=p["image"],
                    gcp_id=targets["gcp_id"].iloc[i],
                    im_x_px=uv[i, 0],
                    im_y_px=uv[i, 1],
                    fully_in_view=inside and seen,
                    distance_m=float(np.linalg.norm(centres[i] - pose.C)),
                )
            )
    cols = ["image", "gcp_id", "im_x_px", "im_y_px", "fully_in_view", "distance_m"]
    return pd.DataFrame(rows, columns=cols)


def digitise(
    truth: pd.DataFrame,
    camera: Camera,
    rng: np.random.Generator,
    click_sigma_px: float,
    max_images_per_target: int,
) -> pd.DataFrame:
    """Observations a person would click: fully visible targets, nearest the image centre first.

    Each target is measured in at most ``max_images_per_target`` images (those where it is
    closest to the image centre, i.e. least distorted), with Gaussian click noise of
    ``click_sigma_px`` per axis. Returns ``image, gcp_id, im_x_px, im_y_px``.

    Parameters
    ----------
    truth : DataFrame
        True pixel positions, as from :func:`target_pixels`.
    camera : Camera
        The camera; its principal point is the image centre used.
    rng : numpy.random.Generator
        Random stream for the click noise.
    click_sigma_px : float
        Standard deviation of the click noise per axis (px).
    max_images_per_target : int
        Most images in which a target is measured.

    Returns
    -------
    DataFrame
        One row per click, sorted by image and target.
    """
    vis = truth[truth["fully_in_view"]].copy()
    vis["r_px"] = np.hypot(vis["im_x_px"] - camera.cx, vis["im_y_px"] - camera.cy)
    picked = vis.sort_values(["gcp_id", "r_px", "image"]).groupby("gcp_id", sort=True).head(max_images_per_target)
    picked = picked.sort_values(["image", "gcp_id"]).reset_index(drop=True)
    noise = rng.normal(0.0, click_sigma_px, size=(len(picked), 2))
    return pd.DataFrame(
        {
            "image": picked["image"],
            "gcp_id": picked["gcp_id"],
            "im_x_px": picked["im_x_px"].to_numpy() + noise[:, 0],
            "im_y_px": picked["im_y_px"].to_numpy() + noise[:, 1],
        }
    )


def write_odm_gcp_list(path: str | Path, crs: str, observations: pd.DataFrame, survey: pd.DataFrame) -> None:
    """Write an OpenDroneMap ``gcp_list.txt``: projection line, then one observation per line.

    ``geo_x geo_y geo_z im_x im_y image_name gcp_name`` with the surveyed coordinates.

    Parameters
    ----------
    path : str or Path
        The file; its parent folder is created.
    crs : str
        Projection line (the survey's CRS).
    observations : DataFrame
        Image observations: ``image``, ``gcp_id``, ``im_x_px``, ``im_y_px``.
    survey : DataFrame
        Surveyed targets: ``gcp_id``, ``x``, ``y``, ``z`` (m); InputError when an observed target is
        missing.
    """
    sv = survey.set_index(survey["gcp_id"].astype(str))
    lines = [crs]
    for _, o in observations.iterrows():
        g = str(o["gcp_id"])
        if g not in sv.index:
            raise InputError(f"gcp survey: target '{g}' seen in the images has no surveyed coordinates")
        s = sv.loc[g]
        lines.append(f"{s['x']:.3f} {s['y']:.3f} {s['z']:.3f} {o['im_x_px']:.2f} {o['im_y_px']:.2f} {o['image']} {g}")
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    Path(path).write_text("\n".join(lines) + "\n", encoding="utf-8")


def read_odm_gcp_list(path: str | Path) -> tuple[str, pd.DataFrame]:
    """Parse a ``gcp_list.txt``: returns the projection line and a table of observations."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8").splitlines()
    except OSError as exc:
        raise InputError(f"{path}: cannot read GCP list ({exc})") from None
    if not text:
        raise InputError(f"{path}: GCP list is empty (no projection line)")
    rows = []
    for n, line in enumerate(text[1:], start=2):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        f = line.split()
        if len(f) < 7:
            raise InputError(f"{path}: line {n} has {len(f)} fields, expected 7 (geo_x geo_y geo_z im_x im_y image gcp)")
        try:
            vals = [float(v) for v in f[:5]]
        except ValueError:
            raise InputError(f"{path}: line {n} has a non-numeric coordinate") from None
        rows.append(dict(geo_x=vals[0], geo_y=vals[1], geo_z=vals[2], im_x_px=vals[3], im_y_px=vals[4], image=f[5], gcp_id=f[6]))
    return text[0].strip(), pd.DataFrame(rows, columns=["geo_x", "geo_y", "geo_z", "im_x_px", "im_y_px", "image", "gcp_id"])
