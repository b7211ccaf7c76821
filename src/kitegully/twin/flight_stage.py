"""The flight stage's products, one function per rule (issue 4): the simulated kite flight,
its photos with the GCP observations and coverage, and its figures.

:func:`fly_kite` (rule ``flight_simulate``), :func:`photograph_flight` (rule
``flight_render``), :func:`flight_map` and :func:`sample_images` (rule ``flight_figures``).
The scripts only read the inputs and write what these return.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numba
import numpy as np
import pandas as pd
from scipy import ndimage

from kitegully import InputError
from kitegully.io.figures import map_axes, new_figure
from kitegully.io.raster import GridSpec
from kitegully.seeds import epoch_rng, epoch_seed
from kitegully.twin.camera import Camera, camera_from_config
from kitegully.twin.flight import FlightSettings, pose_from_row, simulate_flight, tether_kite_offset
from kitegully.twin.flight_gcps import digitise, target_pixels
from kitegully.twin.render import Photographic
from kitegully.twin.render_flight import core_mask, coverage, load_scene, render_flight

if TYPE_CHECKING:
    from matplotlib.figure import Figure

log = logging.getLogger(__name__)


# --------------------------------------------------------------------------- flight_simulate
@dataclass
class KiteFlight:
    """Products of :func:`fly_kite` (tables as written by the rule)."""

    poses: pd.DataFrame
    camera_track: pd.DataFrame
    operator_track: pd.DataFrame
    camera_gps: pd.DataFrame
    operator_gps: pd.DataFrame
    strips: pd.DataFrame


def fly_kite(
    extent: tuple[float, float, float, float],
    dtm: np.ndarray,
    grid: GridSpec,
    flight_cfg: Mapping[str, Any],
    tether_cfg: Mapping[str, Any],
    seed: int,
    epoch: int = 1,
) -> KiteFlight:
    """Simulate the kite flight over a twin: true poses, tracks (1 s steps) and GPS logs.

    Parameters
    ----------
    extent : (xmin, ymin, xmax, ymax)
        The twin's site extent (m).
    dtm, grid : the twin's truth DTM (NaN nodata) and its grid: the operator walks on it.
    flight_cfg : mapping
        The ``flight:`` section (:class:`FlightSettings`, camera, material, kite, wind).
    tether_cfg : mapping
        The line model keys of ``tether:`` (lines, kites, kite_model, atmosphere, segment_length_m).
    seed : int
        The run's seed.
    epoch : int
        Survey epoch (issue 17): its own random stream (:func:`kitegully.seeds.epoch_rng`;
        epoch 1 keeps the stream it always had).
    """
    settings = FlightSettings.from_config(flight_cfg, flight_cfg["line_lengths_m"])
    camera = camera_from_config(flight_cfg["camera"])
    dtm_filled = np.where(np.isfinite(dtm), dtm, np.nanmedian(dtm))

    def ground_z(x, y):
        """Bilinear DTM height; beyond the twin the edge value (the operator may walk off-site)."""
        r, c = grid.rowcol(x, y)
        return ndimage.map_coordinates(dtm_filled, [np.asarray(r), np.asarray(c)], order=1, mode="nearest")

    offset = tether_kite_offset(tether_cfg, flight_cfg["material"], flight_cfg["kite"], flight_cfg["wind_speed_m_s"])
    rng = epoch_rng(seed, epoch, "flight", "simulate")
    res = simulate_flight(extent, camera, settings, offset, ground_z, rng)
    log.info("%d strips, %d shots, %d kept, %.0f s of walking", len(res.strips), res.n_triggers, len(res.poses),
             res.summary["flight_duration_s"])
    decim = max(1, int(round(1.0 / settings.time_step_s)))
    strips = pd.DataFrame(
        [
            dict(strip=s.index, operator_start_x_m=s.start[0], operator_start_y_m=s.start[1], operator_end_x_m=s.end[0],
                 operator_end_y_m=s.end[1], line_length_m=s.line_length_m, kite_downwind_m=s.downwind_m,
                 camera_height_m=s.height_m, footprint_along_m=s.footprint_along_m,
                 footprint_across_m=s.footprint_across_m, keep_every_nth_shot=s.keep_every)
            for s in res.strips
        ]
    )
    return KiteFlight(
        res.poses,
        res.camera_track.iloc[::decim].reset_index(drop=True),
        res.operator_track.iloc[::decim].reset_index(drop=True),
        res.camera_gps,
        res.operator_gps,
        strips,
    )


# --------------------------------------------------------------------------- flight_render
@dataclass
class FlightPhotos:
    """Products of :func:`photograph_flight` besides the JPEGs it writes."""

    camera: Camera
    gcp_pixels: pd.DataFrame
    gcp_observations: pd.DataFrame
    survey: pd.DataFrame
    coverage: np.ndarray
    coverage_grid: GridSpec
    image_stats: pd.DataFrame
    summary: pd.DataFrame


def _check_columns(path: str, df: pd.DataFrame, cols: list[str]) -> None:
    missing = [c for c in cols if c not in df.columns]
    if missing:
        raise InputError(f"{path}: missing column(s) {', '.join(missing)}")


def photograph_flight(
    poses_path: str,
    dsm_path: str,
    texture_path: str,
    targets_path: str,
    survey_path: str,
    extent: tuple[float, float, float, float],
    images_dir: str | Path,
    flight_cfg: Mapping[str, Any],
    seed: int,
    crs: str,
    threads: int,
    epoch: int = 1,
) -> FlightPhotos:
    """Render the flight's photos into ``images_dir``, digitise the GCPs and count the coverage.

    Parameters
    ----------
    poses_path, dsm_path, texture_path, targets_path, survey_path : paths
        The true poses (``flight_simulate``), the twin's truth DSM, texture and targets,
        and its observed GCP survey.
    extent : (xmin, ymin, xmax, ymax)
        The twin's site extent (m).
    images_dir : path
        Folder the JPEGs (with EXIF) are written to.
    flight_cfg : mapping
        The ``flight:`` section (``camera``, ``render``, ``gcps``, ``coverage``).
    seed : int
        The run's seed.
    crs : str
        Site CRS (coverage grid).
    threads : int
        Rendering threads (numba).
    epoch : int
        Survey epoch (issue 17): its own render and digitising streams
        (:mod:`kitegully.seeds`; epoch 1 keeps the streams it always had).

    Returns
    -------
    FlightPhotos
        The ``summary`` table holds the images, GSD, overlap, coverage of the core, GCP
        counts and render times.

    Notes
    -----
    Rendering is O(images × pixels × supersampling²) ray casts (numba, ``threads``).

    Over ~80 lines with its docstring on purpose: it is orchestration only (read the
    truth, render, digitise GCPs, count coverage, write the summary), each step one call of
    a function of :mod:`kitegully.twin` in the order the seeded streams expect.
    """
    numba.set_num_threads(max(1, min(threads, numba.config.NUMBA_NUM_THREADS)))
    rcfg, gcfg, ccfg = flight_cfg["render"], flight_cfg["gcps"], flight_cfg["coverage"]
    camera = camera_from_config(flight_cfg["camera"])
    poses = pd.read_csv(poses_path)
    if poses.empty:
        raise InputError(f"{poses_path}: the flight produced no images")

    t0 = time.perf_counter()
    scene, channels = load_scene(dsm_path, texture_path, rcfg["channels"], rcfg["block_cells"])
    log.info("scene: DSM %s, texture %d bands, %d mip levels (%.1f s)", scene.dsm.shape, scene.nbands,
             len(scene.tex_offsets), time.perf_counter() - t0)
    bg = list(rcfg["background_reflectance"])[: len(channels)]
    bg += [bg[-1]] * (len(channels) - len(bg))
    t1 = time.perf_counter()
    c1 = time.process_time()
    stats = render_flight(scene, camera, poses, images_dir, Photographic.from_config(rcfg),
                          epoch_seed(seed, epoch, "flight", "render"), channels, rcfg["supersampling"], bg,
                          rcfg["jpeg_quality"])
    render_s = time.perf_counter() - t1
    render_cpu_s = time.process_time() - c1  # CPU seconds of all threads: independent of other load

    targets = pd.read_csv(targets_path)
    survey = pd.read_csv(survey_path)
    _check_columns(targets_path, targets, ["gcp_id", "x", "y", "z", "size_m"])
    _check_columns(survey_path, survey, ["gcp_id", "x", "y", "z"])
    truth = target_pixels(camera, poses, targets, scene, gcfg["edge_margin_px"], gcfg["occlusion_tolerance_m"])
    rng = epoch_rng(seed, epoch, "flight", "gcps")
    obs = digitise(truth, camera, rng, gcfg["click_sigma_px"], gcfg["max_images_per_target"])
    per_target = obs.groupby("gcp_id").size().reindex(targets["gcp_id"], fill_value=0)
    for g, n in per_target.items():
        if n < gcfg["min_images_per_target"]:
            log.warning("target %s digitised in %d image(s) only (fewer than %d): the flight does not see it more often",
                        g, n, gcfg["min_images_per_target"])
    log.info("GCP list: %d observations of %d targets", len(obs), int((per_target > 0).sum()))

    xs, ys, counts, overlap = coverage(camera, poses, scene, extent, ccfg["cell_m"])
    core = core_mask(xs, ys, extent, ccfg["core_buffer_m"])
    cov_grid = GridSpec(extent[0], extent[3], ccfg["cell_m"], len(xs), len(ys), crs)
    stats = stats.merge(poses[["image", "strip", "z_m"]], on="image")
    core_counts = counts[core] if core.any() else counts.ravel()
    summary = flight_summary(poses, stats, overlap, core_counts, obs, per_target, ccfg["min_images"], render_s,
                             render_cpu_s, threads)
    log.info("summary:\n%s", summary.to_string(index=False))
    if core_counts.min() < ccfg["min_images"]:
        log.warning("some core ground points are seen by fewer than %d images (min %d): SfM may leave gaps",
                    ccfg["min_images"], int(core_counts.min()))
    return FlightPhotos(camera, truth, obs, survey, counts.astype(np.float32), cov_grid, stats, summary)


def flight_summary(
    poses: pd.DataFrame,
    stats: pd.DataFrame,
    overlap: pd.DataFrame,
    core_counts: np.ndarray,
    obs: pd.DataFrame,
    per_target: pd.Series,
    min_images: int,
    render_s: float,
    render_cpu_s: float,
    threads: int,
) -> pd.DataFrame:
    """The ``flight_summary.csv`` table (``quantity, value, unit``) of :func:`photograph_flight`.

    ``core_counts``: images per ground point in the site's core; ``per_target``: GCP
    observations per target; ``min_images``: ``flight.coverage.min_images``.

    Parameters
    ----------
    poses : DataFrame
        True poses, one row per image (``strip``).
    stats : DataFrame
        Per-image facts of :func:`kitegully.twin.render_flight.render_flight` (``gsd_m``, ``blur_px``).
    overlap : DataFrame
        Forward overlap per image pair (``forward_overlap``), from
        :func:`kitegully.twin.render_flight.coverage`.
    core_counts : ndarray
        Images per ground point in the core.
    obs : DataFrame
        The digitised GCP observations.
    per_target : Series
        GCP observations per target.
    min_images : int
        ``flight.coverage.min_images``.
    render_s : float
        Wall-clock rendering time (s).
    render_cpu_s : float
        CPU time of all rendering threads (s).
    threads : int
        Rendering threads.

    Returns
    -------
    DataFrame
        Columns ``quantity, value, unit``, one row per quantity.
    """
    return pd.DataFrame(
        [
            ("images", len(poses), "count"),
            ("strips", poses["strip"].nunique(), "count"),
            ("gsd_min", stats["gsd_m"].min(), "m"),
            ("gsd_median", stats["gsd_m"].median(), "m"),
            ("gsd_max", stats["gsd_m"].max(), "m"),
            ("forward_overlap_mean", overlap["forward_overlap"].mean() if len(overlap) else np.nan, "fraction"),
            ("forward_overlap_min", overlap["forward_overlap"].min() if len(overlap) else np.nan, "fraction"),
            ("core_images_per_point_min", int(core_counts.min()), "count"),
            ("core_images_per_point_median", float(np.median(core_counts)), "count"),
            (f"core_share_with_{min_images}_or_more", float(np.mean(core_counts >= min_images)), "fraction"),
            ("motion_blur_max", stats["blur_px"].max(), "px"),
            ("gcp_observations", len(obs), "count"),
            ("gcp_targets_digitised", int((per_target > 0).sum()), "count"),
            ("gcp_targets_min_images", int(per_target.min()) if len(per_target) else 0, "count"),
            ("render_time_total", render_s, "s"),
            ("render_time_per_image", render_s / len(poses), "s"),
            ("render_cpu_time_total", render_cpu_s, "s"),
            ("threads", threads, "count"),
        ],
        columns=["quantity", "value", "unit"],
    )


# --------------------------------------------------------------------------- flight_figures
def image_footprints(camera: Camera, poses: pd.DataFrame, gsd_m: pd.Series) -> list[np.ndarray]:
    """Ground polygons (4 x 2, m) of every image: corners on the plane through the centre ray's ground hit.

    ``gsd_m`` (by image name) gives the ground distance of the centre ray (GSD × focal length in px).

    Parameters
    ----------
    camera : Camera
        The camera.
    poses : DataFrame
        True poses, one row per image (``image`` and the pose columns).
    gsd_m : Series
        GSD (m) by image name.

    Returns
    -------
    list of ndarray (4, 2)
        Corner coordinates (m) of each image's footprint, in the order of ``poses``.
    """
    corners_px = np.array([[-0.5, -0.5], [camera.width - 0.5, -0.5], [camera.width - 0.5, camera.height - 0.5],
                           [-0.5, camera.height - 0.5]])
    rays = camera.rays_camera(corners_px[:, 0], corners_px[:, 1])
    centre_ray = camera.rays_camera(np.array([camera.cx]), np.array([camera.cy]))[0]
    polys = []
    for _, p in poses.iterrows():
        pose = pose_from_row(p)
        depth = gsd_m.loc[p["image"]] * camera.f
        zg = pose.C[2] + depth * (centre_ray @ pose.R)[2]
        d = rays @ pose.R
        t = (zg - pose.C[2]) / d[:, 2]
        polys.append(pose.C[None, :2] + t[:, None] * d[:, :2])
    return polys


def flight_map(
    camera: Camera,
    poses: pd.DataFrame,
    image_stats: pd.DataFrame,
    operator_track: pd.DataFrame,
    survey: pd.DataFrame,
    extent: tuple[float, float, float, float],
    flight_cfg: Mapping[str, Any],
) -> Figure:
    """Map of the simulated flight: image footprints, operator path, camera positions, GCPs, wind.

    ``image_stats`` is indexed by image name (``gsd_m``); ``flight_cfg`` gives the wind
    (``wind_from_deg``, ``wind_speed_m_s``) and ``line_lengths_m`` for the title.

    Parameters
    ----------
    camera : Camera
        The camera.
    poses : DataFrame
        True poses, one row per image (``x_m``, ``y_m``, ``z_m`` and the pose columns).
    image_stats : DataFrame
        Per-image facts.
    operator_track : DataFrame
        The operator's path (``x_m``, ``y_m``).
    survey : DataFrame
        Surveyed GCP targets (``x``, ``y``).
    extent : tuple of float
        The twin's site extent ``(xmin, ymin, xmax, ymax)`` (m).
    flight_cfg : mapping
        The ``flight:`` section.

    Returns
    -------
    matplotlib.figure.Figure
    """
    from matplotlib.collections import PolyCollection

    cfg = flight_cfg
    xmin, ymin, xmax, ymax = extent
    polys = image_footprints(camera, poses, image_stats["gsd_m"])
    op = operator_track
    fig, ax = new_figure(figsize=(7.0, 6.0))
    ax.add_collection(PolyCollection(polys, facecolors="none", edgecolors="0.55", linewidths=0.4, label="image footprints"))
    ax.plot(op["x_m"], op["y_m"], color="tab:brown", lw=0.9, label="operator path")
    sc = ax.scatter(poses["x_m"], poses["y_m"], c=poses["z_m"], cmap="viridis", s=14, zorder=3, label="camera positions")
    fig.colorbar(sc, ax=ax, label="camera elevation (m)")
    ax.plot([xmin, xmax, xmax, xmin, xmin], [ymin, ymin, ymax, ymax, ymin], color="k", lw=1.2, label="twin extent")
    ax.scatter(survey["x"], survey["y"], marker="s", s=18, facecolors="white", edgecolors="red", zorder=4,
               label="GCP targets")
    wind = np.radians(cfg["wind_from_deg"] + 180)
    ax.annotate("", xy=(xmin + 0.12 * (xmax - xmin) * np.sin(wind) + 0.1 * (xmax - xmin), ymax - 0.1 * (ymax - ymin)
                        + 0.12 * (ymax - ymin) * np.cos(wind)),
                xytext=(xmin + 0.1 * (xmax - xmin), ymax - 0.1 * (ymax - ymin)),
                arrowprops=dict(arrowstyle="->", color="tab:blue", lw=1.5))
    ax.text(xmin + 0.1 * (xmax - xmin), ymax - 0.06 * (ymax - ymin), f"wind {cfg['wind_speed_m_s']:g} m/s",
            color="tab:blue", fontsize=7)
    map_axes(ax)
    ax.set_title(f"Simulated kite flight: {len(poses)} images, line {', '.join(f'{v:g}' for v in cfg['line_lengths_m'])} m")
    ax.legend(loc="lower left", fontsize=6, framealpha=0.9)
    return fig


def sample_images(
    camera: Camera,
    poses: pd.DataFrame,
    image_stats: pd.DataFrame,
    observations: pd.DataFrame,
    images_dir: str | Path,
    n_sample_images: int,
) -> Figure:
    """Evenly spaced sample photos with their digitised GCPs, GSD and exposure offset in the titles.

    Parameters
    ----------
    camera : Camera
        The camera; its image shape sets the figure's aspect.
    poses : DataFrame
        True poses, one row per image (``image``).
    image_stats : DataFrame
        Per-image facts indexed by image name (``gsd_m``, ``ev_offset``).
    observations : DataFrame
        Digitised GCPs (``image``, ``gcp_id``, ``im_x_px``, ``im_y_px``).
    images_dir : str or Path
        Folder of the JPEGs.
    n_sample_images : int
        Number of photos shown (at most the number of images).

    Returns
    -------
    matplotlib.figure.Figure
    """
    from PIL import Image

    obs, stats = observations, image_stats
    n = min(n_sample_images, len(poses))
    pick = poses["image"].iloc[np.linspace(0, len(poses) - 1, n).round().astype(int)].tolist()
    ncol = 2 if n > 1 else 1
    nrow = int(np.ceil(n / ncol))
    fig, axes = new_figure(nrow, ncol, figsize=(7.0, 7.0 * nrow / ncol * camera.height / camera.width + 0.4),
                           squeeze=False)
    for ax, name in zip(axes.ravel(), pick):
        ax.imshow(Image.open(f"{images_dir}/{name}"))
        o = obs[obs["image"] == name]
        ax.scatter(o["im_x_px"], o["im_y_px"], s=40, facecolors="none", edgecolors="red", lw=0.8)
        for _, r in o.iterrows():
            ax.text(r["im_x_px"] + 15, r["im_y_px"], r["gcp_id"], color="red", fontsize=6)
        row = stats.loc[name]
        ax.set_title(f"{name}: GSD {row['gsd_m'] * 100:.1f} cm, exposure {row['ev_offset']:+.2f} EV", fontsize=7)
        ax.set_xlabel("image x (px)")
        ax.set_ylabel("image y (px)")
        ax.grid(False)
    for ax in axes.ravel()[n:]:
        ax.axis("off")
    fig.subplots_adjust(hspace=0.4, wspace=0.3)
    return fig
