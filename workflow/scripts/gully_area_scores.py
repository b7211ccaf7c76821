"""Rule gully_area_scores (twin only, evaluation): gully map vs truth polygons, cell by cell."""

import pandas as pd

from kitegully.evaluate.network import area_scores, rasterize_polygons
from kitegully.io.raster import read_raster
from kitegully.io.tables import write_table
from kitegully.io.vectors import read_vector
from kitegully.logs import setup_script_logging

log = setup_script_logging(snakemake.log[0])
truth_polys = read_vector(snakemake.input.truth, crs=snakemake.params.crs)
rows = []
for name, path in (("buffer_and_patches", snakemake.input.gully_map), ("whole_patches", snakemake.input.gully_map_whole)):
    gully, grid = read_raster(path)
    truth = rasterize_polygons(truth_polys, grid) & (gully != 255)
    s = area_scores(gully == 1, truth, grid.cell)
    rows.append({"map_variant": name, **s})
    log.info("area scores (%s): %s", name, s)
write_table(pd.DataFrame(rows), snakemake.output.table, floatfmt=".3f")
