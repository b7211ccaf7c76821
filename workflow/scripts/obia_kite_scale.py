"""Bare-soil map of the site's kite orthophoto (tiled OBIA), with polygons."""

import json


from kitegully.io.raster import read_raster
from kitegully.io.vectors import write_vector
from kitegully.logs import setup_script_logging
from kitegully.obia.classify import eroded_polygons
from kitegully.obia.kite import bare_soil_map
from kitegully.obia.scene import ObiaParams

log = setup_script_logging(snakemake.log[0])
cfg = snakemake.params.obia
params = ObiaParams.from_config(cfg)
thr = bare_soil_map(snakemake.input.orthophoto, snakemake.input.dsm, snakemake.output.bare_soil, params, int(cfg["kite_scale"]["tile_cells"]))
classes, grid = read_raster(snakemake.output.bare_soil)
write_vector(eroded_polygons(classes, grid.transform, grid.crs), snakemake.output.polygons)
with open(snakemake.output.info, "w", encoding="utf-8") as fh:
    json.dump(thr.as_dict(), fh, indent=2)
