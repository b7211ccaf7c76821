"""Rule flight_simulate: true camera poses, tracks and the observed GPS logs of the simulated kite flight."""

from kitegully.io.raster import read_raster
from kitegully.io.tables import write_table
from kitegully.logs import setup_script_logging
from kitegully.twin.flight import read_extent, write_gpx
from kitegully.twin import fly_kite

log = setup_script_logging(snakemake.log[0])
out, crs = snakemake.output, snakemake.params.crs
dtm, grid = read_raster(snakemake.input.dtm)
fl = fly_kite(read_extent(snakemake.input.site), dtm, grid, snakemake.params.flight, snakemake.params.tether,
              snakemake.params.seed, epoch=snakemake.params.epoch)
write_table(fl.poses, out.poses)
write_table(fl.camera_track, out.camera_track, markdown=False)
write_table(fl.operator_track, out.operator_track, markdown=False)
write_gpx(fl.camera_gps, crs, out.camera_gpx, "camera GPS logger")
write_gpx(fl.operator_gps, crs, out.operator_gpx, "operator GPS logger")
write_table(fl.camera_gps, out.camera_gps_csv, markdown=False)
write_table(fl.operator_gps, out.operator_gps_csv, markdown=False)
write_table(fl.strips, out.strips)
