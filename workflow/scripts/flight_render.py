"""Rule flight_render: the flight's photos (JPEG + EXIF), the GCP observations and the coverage summary."""

from kitegully.io.raster import write_raster
from kitegully.io.tables import write_table
from kitegully.logs import setup_script_logging
from kitegully.twin.flight import read_extent
from kitegully.twin.flight_gcps import write_odm_gcp_list
from kitegully.twin import photograph_flight

log = setup_script_logging(snakemake.log[0])
inp, out, crs = snakemake.input, snakemake.output, snakemake.params.crs
ph = photograph_flight(inp.poses, inp.dsm, inp.texture, inp.targets, inp.survey, read_extent(inp.site), out.images,
                       snakemake.params.flight, snakemake.params.seed, crs, snakemake.threads,
                       epoch=snakemake.params.epoch)
ph.camera.write_json(out.camera)
write_table(ph.gcp_pixels, out.gcp_pixels)
write_odm_gcp_list(out.gcp_list, crs, ph.gcp_observations, ph.survey)
write_raster(out.coverage, ph.coverage, ph.coverage_grid)
write_table(ph.image_stats, out.image_stats)
write_table(ph.summary, out.summary)
