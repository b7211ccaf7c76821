"""Rule gully_depth_tile: depth map (smoothed DEM minus DEM) of one tile, read with the kernel radius around it."""

import numpy as np
import rasterio

from kitegully.gully.depth import depth_halo_cells, depth_map_tile
from kitegully.logs import setup_script_logging
from kitegully.terrain.tiling import TilingParams

log = setup_script_logging(snakemake.log[0])
p = snakemake.params
with rasterio.open(snakemake.input.dem) as src:
    shape, cell = (src.height, src.width), abs(src.transform.a)
tile = TilingParams(**p.tiling).tile(shape, snakemake.wildcards.tile)
smoothed, depth = depth_map_tile(snakemake.input.dem, tile, cell, p.sigma_m, p.truncate_sigmas)
np.savez(snakemake.output.tile, smoothed=smoothed, depth=depth)
log.info("depth tile %s: rows %d+%d, cols %d+%d, overlap %d cells", tile.name, tile.r0, tile.h, tile.c0, tile.w,
         depth_halo_cells(cell, p.sigma_m, p.truncate_sigmas))
