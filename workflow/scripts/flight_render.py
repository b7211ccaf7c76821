"""Render the flight's photos (JPEG + EXIF), the GCP observations and the coverage summary."""

import time
import zlib

import numba
import numpy as np
import pandas as pd

from kitegully import InputError
from kitegully.io.raster import write_raster, GridSpec
from kitegully.io.tables import write_table
from kitegully.logs import setup_script_logging
from kitegully.twin.camera import camera_from_config
from kitegully.twin.flight import read_extent
from kitegully.twin.flight_gcps import digitise, target_pixels, write_odm_gcp_list
from kitegully.twin.render import Photographic
from kitegully.twin.render_flight import core_mask, coverage, load_scene, render_flight

log = setup_script_logging(snakemake.log[0])
numba.set_num_threads(max(1, min(snakemake.threads, numba.config.NUMBA_NUM_THREADS)))
cfg = snakemake.params.flight
rcfg, gcfg, ccfg = cfg["render"], cfg["gcps"], cfg["coverage"]
seed = snakemake.params.seed
camera = camera_from_config(cfg["camera"])
camera.write_json(snakemake.output.camera)
extent = read_extent(snakemake.input.site)
poses = pd.read_csv(snakemake.input.poses)
if poses.empty:
    raise InputError(f"{snakemake.input.poses}: the flight produced no images")

t0 = time.perf_counter()
scene, channels = load_scene(snakemake.input.dsm, snakemake.input.texture, rcfg["channels"], rcfg["block_cells"])
log.info("scene: DSM %s, texture %d bands, %d mip levels (%.1f s)", scene.dsm.shape, scene.nbands,
         len(scene.tex_offsets), time.perf_counter() - t0)
bg = list(rcfg["background_reflectance"])[: len(channels)]
bg += [bg[-1]] * (len(channels) - len(bg))
t1 = time.perf_counter()
c1 = time.process_time()
stats = render_flight(scene, camera, poses, snakemake.output.images, Photographic.from_config(rcfg),
                      int(zlib.crc32(b"flight.render") ^ seed), channels, rcfg["supersampling"], bg,
                      rcfg["jpeg_quality"])
render_s = time.perf_counter() - t1
render_cpu_s = time.process_time() - c1  # CPU seconds of all threads: independent of other load

targets = pd.read_csv(snakemake.input.targets)
survey = pd.read_csv(snakemake.input.survey)
for name, df, cols in [(snakemake.input.targets, targets, ["gcp_id", "x", "y", "z", "size_m"]),
                       (snakemake.input.survey, survey, ["gcp_id", "x", "y", "z"])]:
    missing = [c for c in cols if c not in df.columns]
    if missing:
        raise InputError(f"{name}: missing column(s) {', '.join(missing)}")
truth = target_pixels(camera, poses, targets, scene, gcfg["edge_margin_px"], gcfg["occlusion_tolerance_m"])
write_table(truth, snakemake.output.gcp_pixels)
rng = np.random.default_rng([seed, zlib.crc32(b"flight.gcps")])
obs = digitise(truth, camera, rng, gcfg["click_sigma_px"], gcfg["max_images_per_target"])
write_odm_gcp_list(snakemake.output.gcp_list, snakemake.params.crs, obs, survey)
per_target = obs.groupby("gcp_id").size().reindex(targets["gcp_id"], fill_value=0)
for g, n in per_target.items():
    if n < gcfg["min_images_per_target"]:
        log.warning("target %s digitised in %d image(s) only (fewer than %d): the flight does not see it more often",
                    g, n, gcfg["min_images_per_target"])
log.info("GCP list: %d observations of %d targets", len(obs), int((per_target > 0).sum()))

xs, ys, counts, overlap = coverage(camera, poses, scene, extent, ccfg["cell_m"], ccfg["core_buffer_m"])
core = core_mask(xs, ys, extent, ccfg["core_buffer_m"])
cov_grid = GridSpec(extent[0], extent[3], ccfg["cell_m"], len(xs), len(ys), snakemake.params.crs)
write_raster(snakemake.output.coverage, counts.astype(np.float32), cov_grid)
stats = stats.merge(poses[["image", "strip", "z_m"]], on="image")
write_table(stats, snakemake.output.image_stats)
core_counts = counts[core] if core.any() else counts.ravel()
summary = pd.DataFrame(
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
        (f"core_share_with_{ccfg['min_images']}_or_more", float(np.mean(core_counts >= ccfg["min_images"])), "fraction"),
        ("motion_blur_max", stats["blur_px"].max(), "px"),
        ("gcp_observations", len(obs), "count"),
        ("gcp_targets_digitised", int((per_target > 0).sum()), "count"),
        ("gcp_targets_min_images", int(per_target.min()) if len(per_target) else 0, "count"),
        ("render_time_total", render_s, "s"),
        ("render_time_per_image", render_s / len(poses), "s"),
        ("render_cpu_time_total", render_cpu_s, "s"),
        ("threads", snakemake.threads, "count"),
    ],
    columns=["quantity", "value", "unit"],
)
write_table(summary, snakemake.output.summary)
log.info("summary:\n%s", summary.to_string(index=False))
if core_counts.min() < ccfg["min_images"]:
    log.warning("some core ground points are seen by fewer than %d images (min %d): SfM may leave gaps",
                ccfg["min_images"], int(core_counts.min()))
