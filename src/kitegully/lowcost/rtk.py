"""The RTK comparison block (rule ``lowcost_rtk_bundle``): the joint model through the georef stage's GCP bundle."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping

import pandas as pd


def adjust_rtk_bundle(observed_dir: str | Path, sfm_dir: str | Path, georef_cfg: Mapping[str, Any], crs: str, seed: int,
                      out_dir: str | Path) -> dict:
    """The comparison block of issue 18: the same joint model georeferenced by the georef
    stage's GCP bundle adjustment with RTK-grade target coordinates (``targets_rtk.csv``)
    and the target clicks, written as an OpenDroneMap ``gcp_list.txt`` first.

    Returns the georef stage's summary; its products go to ``out_dir`` (model, transform,
    ``gcp_residuals.csv``, ``loo_checkpoints.csv``, ``summary.json``...). Cost: the georef
    stage's bundle adjustment, seconds for 56 photos.

    Parameters
    ----------
    observed_dir : path
        Folder holding ``image_clicks.csv`` and ``targets_rtk.csv``.
    sfm_dir : path
        SfM folder of :func:`survey_lowcost` (``model``, ``image_info.json``).
    georef_cfg : mapping
        The georef stage's section (:class:`kitegully.georef.stage.GeorefParams`).
    crs : str
        Site CRS.
    seed : int
        Seed of the georef stage's tie-point choice.
    out_dir : path
        Output folder, created if missing.

    Returns
    -------
    dict
        The georef stage's summary.
    """
    from kitegully.georef.stage import GeorefParams, georeference
    from kitegully.twin.flight_gcps import write_odm_gcp_list

    obs, sfm, out = Path(observed_dir), Path(sfm_dir), Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    clicks = pd.read_csv(obs / "image_clicks.csv")
    t = clicks[clicks["kind"] == "target"].rename(columns={"point": "gcp_id", "u_px": "im_x_px", "v_px": "im_y_px"})
    rtk = pd.read_csv(obs / "targets_rtk.csv").rename(columns={"target": "gcp_id", "x_m": "x", "y_m": "y", "z_m": "z"})
    gcp_file = out / "gcp_list.txt"
    write_odm_gcp_list(gcp_file, crs, t, rtk)
    names = {"model": "model", "transform": "transform.json", "summary": "summary.json", "residuals": "gcp_residuals.csv",
             "loo": "loo_checkpoints.csv", "calibration": "camera_calibration.csv", "cameras": "camera_positions.gpkg",
             "cloud": "sparse_cloud.laz", "figure": "gcp_residuals.png"}
    return georeference(sfm / "model", sfm / "image_info.json", gcp_file, "stored", GeorefParams.from_config(georef_cfg),
                        crs, seed, {k: out / v for k, v in names.items()})
