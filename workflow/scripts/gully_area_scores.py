"""Rule gully_area_scores (twin only, evaluation): gully map vs truth polygons, cell by cell."""

from kitegully.gully import score_gully_areas
from kitegully.io.raster import read_raster
from kitegully.io.tables import write_table
from kitegully.io.vectors import read_vector
from kitegully.logs import setup_script_logging

log = setup_script_logging(snakemake.log[0])
inp = snakemake.input
maps = {"buffer_and_patches": read_raster(inp.gully_map), "whole_patches": read_raster(inp.gully_map_whole)}
table = score_gully_areas(read_vector(inp.truth, crs=snakemake.params.crs), maps)
write_table(table, snakemake.output.table, floatfmt=".3f")
