"""Rule gully_fill_tile: pass 1 of the tiled Priority-Flood (Barnes 2016) on one tile of the tracing surface."""

import rasterio

from kitegully.logs import setup_script_logging
from kitegully.terrain.tiled_fill import fill_tile, read_tile_with_halo
from kitegully.terrain.tiling import TilingParams

log = setup_script_logging(snakemake.log[0])
with rasterio.open(snakemake.input.surface) as src:
    shape = (src.height, src.width)
tile = TilingParams(**snakemake.params.tiling).tile(shape, snakemake.wildcards.tile)
tf = fill_tile(read_tile_with_halo(snakemake.input.surface, tile), tile)
tf.save(snakemake.output.fill)
tf.summary().save(snakemake.output.summary)
log.info("tile %s: rows %d+%d, cols %d+%d, %d watershed labels, %d label pairs",
         tile.name, tile.r0, tile.h, tile.c0, tile.w, tf.n_labels, tf.edges[0].size)
