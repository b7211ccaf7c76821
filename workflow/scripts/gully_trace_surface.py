"""Rule gully_trace_surface: the surface the network is traced on (holes filled, smoothed), for the tiled fill.

With ``gully.crowns`` the crown mask is made here too, on the whole grid, and written for
``gully_map``: the tiled fill is then made on the surface interpolated under those crowns,
and the map bridges its hidden reaches with the same mask.
"""

import numpy as np

from kitegully.gully import GullyParams, tracing_surface
from kitegully.gully.heads import automatic_head_params
from kitegully.gully.inputs import check_dem, read_orthophoto_on_grid
from kitegully.gully.surface import crowns_on
from kitegully.io.raster import read_raster, write_raster
from kitegully.logs import setup_script_logging
from kitegully.memory import keep_freed_memory

log = setup_script_logging(snakemake.log[0])
keep_freed_memory()
inp = snakemake.input
dem, grid = read_raster(inp.dem)
check_dem(dem, inp.dem, grid.crs, snakemake.params.crs)
params = GullyParams.from_config(snakemake.params.mapping)
dem = np.asarray(dem, dtype=np.float32)
hidden = incision = None
if params.needs_ground_surface:
    incision = automatic_head_params(snakemake.params["heads"], snakemake.params["automatic_heads"], dem, grid,
                                     inp.get("checkpoints"), params.head_snap, needed=True)
if params.crowns.enabled:
    hidden = crowns_on(dem, grid, params, incision, read_orthophoto_on_grid(inp.ortho, grid), snakemake.threads)
    write_raster(snakemake.output.crowns, hidden.astype(np.uint8), grid)
_, z_trace, n_holes = tracing_surface(dem, grid, params, workers=snakemake.threads, incision=incision, hidden=hidden)
write_raster(snakemake.output.surface, z_trace, grid)
log.info("tracing surface: %d x %d cells, %d hole cells interpolated, %s%s", grid.height, grid.width, n_holes,
         z_trace.dtype, "" if hidden is None else f", {int(hidden.sum())} cells under crowns")
