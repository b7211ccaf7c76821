"""Statistics of a COLMAP model for ``summary.json`` and the camera table."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pycolmap

from kitegully.sfm.images import ImageInfo


def model_summary(rec: pycolmap.Reconstruction, infos: list[ImageInfo]) -> dict:
    """Counts, track length, reprojection error and the images left out of the model."""
    registered = {rec.images[i].name.split("/")[-1] for i in rec.reg_image_ids()}
    left_out = [i.name for i in infos if i.sfm_name not in registered]
    n = len(infos)
    return {
        "n_images": n,
        "n_registered": int(rec.num_reg_images()),
        "registration_rate": float(rec.num_reg_images() / n) if n else 0.0,
        "n_points3d": int(rec.num_points3D()),
        "mean_track_length": float(rec.compute_mean_track_length()) if rec.num_points3D() else 0.0,
        "mean_observations_per_image": float(rec.compute_mean_observations_per_reg_image()) if rec.num_reg_images() else 0.0,
        "mean_reprojection_error_px": float(rec.compute_mean_reprojection_error()),
        "images_left_out": left_out,
        "cameras": [camera_record(c) for c in rec.cameras.values()],
    }


def camera_record(cam: pycolmap.Camera) -> dict:
    """A camera's model, size and named parameters."""
    names = [s.strip() for s in cam.params_info.split(",")]
    return {
        "camera_id": int(cam.camera_id),
        "model": cam.model.name,
        "width_px": int(cam.width),
        "height_px": int(cam.height),
        **{f"{k}": float(v) for k, v in zip(names, np.asarray(cam.params))},
    }


def image_table(rec: pycolmap.Reconstruction, infos: list[ImageInfo]) -> pd.DataFrame:
    """One row per input image: frame information and whether it was registered."""
    by_name = {rec.images[i].name.split("/")[-1]: rec.images[i] for i in rec.reg_image_ids()}
    rows = []
    for info in infos:
        img = by_name.get(info.sfm_name)
        row = info.as_row()
        row["registered"] = img is not None
        row["n_points3d"] = int(img.num_points3D) if img is not None else 0
        rows.append(row)
    df = pd.DataFrame(rows)
    return df.rename(columns={"stored_width": "stored_width_px", "stored_height": "stored_height_px",
                              "sfm_width": "sfm_width_px", "sfm_height": "sfm_height_px"})
