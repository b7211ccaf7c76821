"""Rule gully_trace_surface: the surface the network is traced on (holes filled, smoothed), for the tiled fill."""

import numpy as np

from kitegully.gully import GullyParams, tracing_surface
from kitegully.gully.inputs import check_dem
from kitegully.io.raster import read_raster, write_raster
from kitegully.logs import setup_script_logging

log = setup_script_logging(snakemake.log[0])
dem, grid = read_raster(snakemake.input.dem)
check_dem(dem, snakemake.input.dem, grid.crs, snakemake.params.crs)
params = GullyParams.from_config(snakemake.params.mapping)
_, z_trace, n_holes = tracing_surface(np.asarray(dem, dtype=np.float32), grid, params, workers=snakemake.threads)
write_raster(snakemake.output.surface, z_trace, grid)
log.info("tracing surface: %d x %d cells, %d hole cells interpolated, %s", grid.height, grid.width, n_holes, z_trace.dtype)
