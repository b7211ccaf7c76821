"""Simulate the kite flight: true camera poses, tracks and the observed GPS logs."""

import zlib

import numpy as np
import pandas as pd
from scipy import ndimage

from kitegully.io.raster import read_raster
from kitegully.io.tables import write_table
from kitegully.logs import setup_script_logging
from kitegully.twin.camera import camera_from_config
from kitegully.twin.flight import FlightSettings, read_extent, simulate_flight, tether_kite_offset, write_gpx

log = setup_script_logging(snakemake.log[0])
cfg = snakemake.params.flight
settings = FlightSettings.from_config(cfg, cfg["line_lengths_m"])
camera = camera_from_config(cfg["camera"])
extent = read_extent(snakemake.input.site)
dtm, grid = read_raster(snakemake.input.dtm)
dtm_filled = np.where(np.isfinite(dtm), dtm, np.nanmedian(dtm))


def ground_z(x, y):
    """Bilinear DTM height; beyond the twin the edge value (the operator may walk off-site)."""
    r, c = grid.rowcol(x, y)
    return ndimage.map_coordinates(dtm_filled, [np.asarray(r), np.asarray(c)], order=1, mode="nearest")


offset = tether_kite_offset(snakemake.params.tether, cfg["material"], cfg["kite"], cfg["wind_speed_m_s"])
rng = np.random.default_rng([snakemake.params.seed, zlib.crc32(b"flight.simulate")])
res = simulate_flight(extent, camera, settings, offset, ground_z, rng)
log.info("%d strips, %d shots, %d kept, %.0f s of walking", len(res.strips), res.n_triggers, len(res.poses),
         res.summary["flight_duration_s"])

write_table(res.poses, snakemake.output.poses)
decim = max(1, int(round(1.0 / settings.time_step_s)))
write_table(res.camera_track.iloc[::decim].reset_index(drop=True), snakemake.output.camera_track, markdown=False)
write_table(res.operator_track.iloc[::decim].reset_index(drop=True), snakemake.output.operator_track, markdown=False)
crs = snakemake.params.crs
write_gpx(res.camera_gps, crs, snakemake.output.camera_gpx, "camera GPS logger")
write_gpx(res.operator_gps, crs, snakemake.output.operator_gpx, "operator GPS logger")
write_table(res.camera_gps, snakemake.output.camera_gps_csv, markdown=False)
write_table(res.operator_gps, snakemake.output.operator_gps_csv, markdown=False)
strips = pd.DataFrame(
    [
        dict(strip=s.index, operator_start_x_m=s.start[0], operator_start_y_m=s.start[1], operator_end_x_m=s.end[0],
             operator_end_y_m=s.end[1], line_length_m=s.line_length_m, kite_downwind_m=s.downwind_m,
             camera_height_m=s.height_m, footprint_along_m=s.footprint_along_m,
             footprint_across_m=s.footprint_across_m, keep_every_nth_shot=s.keep_every)
        for s in res.strips
    ]
)
write_table(strips, snakemake.output.strips)
