"""Rule obia_kite_scale: bare-soil map of the site's kite orthophoto (tiled OBIA), polygons and a map figure."""

import json

from kitegully.io.figures import save_figure
from kitegully.io.raster import read_raster
from kitegully.io.vectors import write_vector
from kitegully.logs import setup_script_logging
from kitegully.obia.classify import eroded_polygons
from kitegully.obia.kite import bare_soil_map
from kitegully.obia import kite_map_figure
from kitegully.obia.scene import ObiaParams

log = setup_script_logging(snakemake.log[0])
inp, out, cfg = snakemake.input, snakemake.output, snakemake.params.obia
params = ObiaParams.from_config(cfg)
thr = bare_soil_map(inp.orthophoto, inp.dsm, out.bare_soil, params, int(snakemake.params.tile_cells))
classes, grid = read_raster(out.bare_soil)
polygons = eroded_polygons(classes, grid.transform, grid.crs)
write_vector(polygons, out.polygons)
with open(out.info, "w", encoding="utf-8") as fh:
    json.dump(thr.as_dict(), fh, indent=2)
bare = classes == 1
log.info("bare soil: %.1f m² in %d polygons (%.2f %% of the mapped cells)", float(bare.sum() * grid.cell ** 2),
         len(polygons), 100.0 * bare.sum() / max(int((classes != 255).sum()), 1))
fig = kite_map_figure(inp.orthophoto, classes, grid, thr, snakemake.params.figure_max_px, params.index)
save_figure(fig, out.figure, attribution=snakemake.params.attribution)
