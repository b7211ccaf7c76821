"""Writing the georeferenced products: COLMAP model, calibration table, camera positions,
sparse cloud (LAZ, or LAS as an option) and the residual-vector figure.

The COLMAP model is written in the *local* frame: site CRS coordinates minus the offset
stored in ``transform.json`` (``offset_m``), so single-precision consumers (dense
matching) keep millimetres. Every other product is in the site CRS itself.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import TYPE_CHECKING

import geopandas as gpd
import laspy
import numpy as np
import pandas as pd
import pycolmap
from pyproj import CRS
from shapely.geometry import Point

from kitegully.georef.bundle import Block
from kitegully.georef.geometry import camera_centres, rotvec_to_matrix
from kitegully.georef.model import ModelIndex, write_block_to_reconstruction
from kitegully.io.figures import map_axes, new_figure, save_figure
from kitegully.io.tables import write_table

if TYPE_CHECKING:
    from typing import Any


def write_model(rec: pycolmap.Reconstruction, block: Block, index: ModelIndex, out_dir: str | Path) -> pycolmap.Reconstruction:
    """Write the adjusted model (COLMAP binary) in the local frame; returns it.

    Parameters
    ----------
    rec : pycolmap.Reconstruction
        The SfM model; it is updated in place.
    block : Block
        The adjusted block in the local frame.
    index : ModelIndex
        Ids that tie the block's rows to ``rec``.
    out_dir : str or Path
        Output folder; removed first if it exists.

    Returns
    -------
    pycolmap.Reconstruction
        ``rec`` with the adjusted poses, intrinsics and points.
    """
    out_dir = Path(out_dir)
    if out_dir.exists():
        shutil.rmtree(out_dir)
    out_dir.mkdir(parents=True)
    rec = write_block_to_reconstruction(rec, block, index)
    rec.write(out_dir)
    return rec


def write_transform(path: str | Path, crs: str, offset: np.ndarray, sim_dict: dict, report: dict) -> None:
    """``transform.json``: site CRS, local-frame offset, model→local similarity, run report.

    Parameters
    ----------
    path : str or Path
        Output JSON file.
    crs : str
        Site CRS.
    offset : ndarray (3,)
        Offset of the local frame (m), ``site = local + offset``.
    sim_dict : dict
        The model → local similarity as a dict.
    report : dict
        Run report; NumPy values and NaN/inf are made JSON-safe (NaN/inf as null).
    """
    doc = {"crs": crs, "offset_m": [float(v) for v in offset], "model_to_local": sim_dict, "report": report}
    Path(path).write_text(json.dumps(clean_json(doc), indent=2) + "\n", encoding="utf-8")


def clean_json(o: Any) -> Any:
    """A JSON-safe copy: NumPy scalars/arrays to Python, NaN/inf to None."""
    if isinstance(o, dict):
        return {str(k): clean_json(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [clean_json(v) for v in o]
    if isinstance(o, np.ndarray):
        return clean_json(o.tolist())
    if isinstance(o, (np.bool_,)):
        return bool(o)
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, (float, np.floating)):
        return float(o) if np.isfinite(o) else None
    return o


def calibration_table(start: Block, adjusted: Block, index: ModelIndex, rec: pycolmap.Reconstruction) -> pd.DataFrame:
    """One row per camera: model, size and intrinsics from SfM and after the GCP adjustment.

    Parameters
    ----------
    start : Block
        The block before the GCP adjustment (SfM intrinsics).
    adjusted : Block
        The block after the GCP adjustment.
    index : ModelIndex
        Ids that tie the block's rows to ``rec``.
    rec : pycolmap.Reconstruction
        The model, for each camera's model name and size.

    Returns
    -------
    DataFrame
        ``camera_id``, ``model``, ``width_px``, ``height_px``, ``f_px``, ``cx_px``, ``cy_px``,
        ``k1`` and ``k2`` with ``_sfm`` and ``_adjusted`` suffixes, and ``n_images``.
    """
    rows = []
    for k, cid in enumerate(index.camera_ids):
        cam = rec.cameras[int(cid)]
        row = {"camera_id": int(cid), "model": cam.model.name, "width_px": int(cam.width), "height_px": int(cam.height)}
        for j, name in enumerate(("f_px", "cx_px", "cy_px", "k1", "k2")):
            row[f"{name}_sfm"] = float(start.intr[k, j])
            row[f"{name}_adjusted"] = float(adjusted.intr[k, j])
        row["n_images"] = int(np.sum(adjusted.cam_of_image == k))
        rows.append(row)
    return pd.DataFrame(rows)


def camera_positions(block: Block, index: ModelIndex, offset: np.ndarray, crs: str,
                     original_names: dict[str, str] | None = None) -> gpd.GeoDataFrame:
    """Projection centres (3-D points, site CRS) with omega/phi/kappa (deg) and image names.

    ``original_names`` maps the prepared SfM file names to the input file names.

    Parameters
    ----------
    block : Block
        The adjusted block in the local frame.
    index : ModelIndex
        Ids that tie the block's rows to the model (image names).
    offset : ndarray (3,)
        Offset of the local frame (m), added to the centres.
    crs : str
        Site CRS of the result.
    original_names : dict of str to str or None
        Prepared SfM file name → input file name; names not in it are kept as they are.

    Returns
    -------
    GeoDataFrame
        One 3-D point per image with ``image``, ``sfm_image``, ``x_m``, ``y_m``, ``z_m``,
        ``omega_deg``, ``phi_deg``, ``kappa_deg`` and ``tilt_from_nadir_deg``.
    """
    original_names = original_names or {}
    C = camera_centres(block.rv, block.t) + offset
    R = rotvec_to_matrix(block.rv)  # camera from world
    # photogrammetric angles of the world-from-camera rotation, [I] omega-phi-kappa convention
    M = np.transpose(R, (0, 2, 1))
    omega = np.degrees(np.arctan2(-M[:, 1, 2], M[:, 2, 2]))
    phi = np.degrees(np.arcsin(np.clip(M[:, 0, 2], -1, 1)))
    kappa = np.degrees(np.arctan2(-M[:, 0, 1], M[:, 0, 0]))
    view = M[:, :, 2]
    tilt = np.degrees(np.arccos(np.clip(-view[:, 2], -1, 1)))
    df = pd.DataFrame({
        "image": [original_names.get(n.split("/")[-1], n.split("/")[-1]) for n in index.image_names],
        "sfm_image": [n.split("/")[-1] for n in index.image_names],
        "x_m": C[:, 0], "y_m": C[:, 1], "z_m": C[:, 2],
        "omega_deg": omega, "phi_deg": phi, "kappa_deg": kappa, "tilt_from_nadir_deg": tilt,
    })
    return gpd.GeoDataFrame(df, geometry=[Point(x, y, z) for x, y, z in C], crs=crs)


def write_las(rec: pycolmap.Reconstruction, offset: np.ndarray, crs: str, path: str | Path) -> int:
    """Sparse cloud as LAS 1.4 (point format 7: xyz, RGB, and the track length as intensity).

    Parameters
    ----------
    rec
        The georeferenced model (points in the local frame).
    offset
        Local-frame offset added to every point (site CRS, m).
    crs
        Site CRS, stored in the header (WKT VLR).
    path
        Output file; a ``.laz`` suffix compresses with LASzip (laspy's ``lazrs``
        backend), ``.las`` writes it uncompressed. The points are the same either way.

    Returns
    -------
    int
        Number of points written.
    """
    path = Path(path)
    if path.suffix.lower() not in (".las", ".laz"):
        raise ValueError(f"{path}: point cloud files end in .laz or .las")
    pts = list(rec.points3D.values())
    xyz = np.array([p.xyz for p in pts]).reshape(-1, 3) + offset
    rgb = np.array([p.color for p in pts], dtype=np.uint16).reshape(-1, 3) * 257
    tl = np.array([p.track.length() for p in pts], dtype=np.uint16)
    header = laspy.LasHeader(point_format=7, version="1.4")
    header.offsets = np.floor(xyz.min(axis=0)) if len(xyz) else np.zeros(3)
    header.scales = np.array([0.001, 0.001, 0.001])
    header.add_crs(CRS.from_user_input(crs))
    las = laspy.LasData(header)
    las.x, las.y, las.z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    las.red, las.green, las.blue = rgb[:, 0], rgb[:, 1], rgb[:, 2]
    las.intensity = tl
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.suffix.lower() == ".laz":
        las.write(str(path), do_compress=True, laz_backend=laspy.LazBackend.Lazrs)
    else:
        las.write(str(path), do_compress=False)
    return len(xyz)


def residual_figure(
    residuals: pd.DataFrame, loo: pd.DataFrame, survey: dict[str, np.ndarray], cameras: gpd.GeoDataFrame,
    path: str | Path, arrow_scale: float | None, attribution: str | None = None,
) -> None:
    """Map of GCP residual vectors: plan arrows (after adjustment: black; leave-one-out:
    orange, dashed) and the vertical residual as a filled circle on a diverging scale.

    Parameters
    ----------
    residuals : DataFrame
        Residuals of every GCP after the adjustment (columns ``gcp_id``, ``dx_m``, ``dy_m``,
        ``dz_m``, ``used``).
    loo : DataFrame
        Leave-one-out residuals of the used GCPs.
    survey : dict of str to ndarray (3,)
        Surveyed position of each GCP (site CRS, m), by GCP id.
    cameras : GeoDataFrame
        Camera positions (columns ``x_m``, ``y_m``).
    path : str or Path
        Output PNG file.
    arrow_scale : float or None
        Exaggeration of the plan arrows; None picks one so the largest arrow is 15 % of the
        plotted extent.
    attribution : str or None
        Line written below the figure.
    """
    fig, ax = new_figure(figsize=(6.5, 5.5))
    ax.scatter(cameras["x_m"], cameras["y_m"], s=6, c="0.6", marker="^", label="camera positions", zorder=1)
    xy = np.array([survey[g][:2] for g in residuals["gcp_id"]])
    for g, (x, y) in zip(residuals["gcp_id"], xy):
        ax.annotate(g, (x, y), xytext=(5, 5), textcoords="offset points", fontsize=7)
    res = residuals.dropna(subset=["dx_m"])
    lo = loo.dropna(subset=["dx_m"])
    extent = max(np.ptp(np.r_[xy[:, 0], cameras["x_m"]]), np.ptp(np.r_[xy[:, 1], cameras["y_m"]]), 1.0)
    mags = np.r_[np.hypot(res["dx_m"], res["dy_m"]), np.hypot(lo["dx_m"], lo["dy_m"])]
    big = float(np.nanmax(mags)) if len(mags) else 1.0
    scale = arrow_scale or (0.15 * extent / max(big, 1e-9))
    unused = ~residuals["used"].to_numpy(bool)
    ax.scatter(xy[unused, 0], xy[unused, 1], s=40, facecolors="none", edgecolors="k", linewidths=0.8,
               label="GCP not used", zorder=2)
    dz = res["dz_m"].to_numpy(float)
    vmax = max(float(np.nanmax(np.abs(dz))) if len(dz) else 1.0, 1e-6)
    if len(res):
        p = np.array([survey[g][:2] for g in res["gcp_id"]])
        sc = ax.scatter(p[:, 0], p[:, 1], c=dz, cmap="RdBu_r", vmin=-vmax, vmax=vmax, s=60, edgecolors="k",
                        linewidths=0.6, zorder=3, label="GCP (colour: dz after adjustment)")
        cb = fig.colorbar(sc, ax=ax, shrink=0.8)
        cb.set_label("vertical residual dz (m)")
        q = ax.quiver(p[:, 0], p[:, 1], res["dx_m"] * scale, res["dy_m"] * scale, angles="xy", scale_units="xy", scale=1,
                      color="k", width=0.006, zorder=4, label="plan residual after adjustment")
        # a reference arrow at the same exaggeration: the largest round length (1, 2 or 5 x 10^k m) up to the largest arrow
        decade = 10.0 ** np.floor(np.log10(max(big, 1e-9)))
        ref = float(max(m * decade for m in (1, 2, 5) if m * decade <= max(big, decade)))
        times = f"{scale:.0f}" if scale >= 10 else f"{scale:.3g}"
        ax.quiverkey(q, 0.62, 1.04, ref * scale, f"{ref:g} m (arrows × {times})", labelpos="E", coordinates="axes",
                     fontproperties={"size": 7})
    if len(lo):
        p = np.array([survey[g][:2] for g in lo["gcp_id"]])
        ax.quiver(p[:, 0], p[:, 1], lo["dx_m"] * scale, lo["dy_m"] * scale, angles="xy", scale_units="xy", scale=1,
                  color="tab:orange", width=0.004, linestyle="--", zorder=4, label="leave-one-out plan residual")
    map_axes(ax)
    ax.tick_params(axis="x", labelrotation=30)
    ax.set_title("GCP residuals", loc="left")
    # below the map: GCPs lie all over the site, so no corner inside is free
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.2), ncol=2, fontsize=7, frameon=False)
    save_figure(fig, path, attribution=attribution)


def write_residual_tables(residuals: pd.DataFrame, loo: pd.DataFrame, res_path: str | Path, loo_path: str | Path) -> None:
    """Write the GCP residual and leave-one-out tables (CSV, each with a Markdown copy beside it).

    Parameters
    ----------
    residuals : DataFrame
        Residuals of every GCP after the adjustment.
    loo : DataFrame
        Leave-one-out residuals of the used GCPs.
    res_path, loo_path : path
        CSV files of the two tables.
    """
    write_table(residuals, res_path)
    write_table(loo, loo_path)
