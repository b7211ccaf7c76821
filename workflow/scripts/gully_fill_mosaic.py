"""Rule gully_fill_mosaic: pass 3 of the tiled Priority-Flood per tile (max of fill and spill), written as one raster."""

import rasterio

from kitegully.logs import setup_script_logging
from kitegully.terrain.tiled_fill import SpillElevations, TileFill, finalise_tile
from kitegully.terrain.tiling import TilingParams, write_mosaic

log = setup_script_logging(snakemake.log[0])
surface = snakemake.input.surface
with rasterio.open(surface) as src:
    shape, dtype = (src.height, src.width), src.dtypes[0]
tiling = TilingParams(**snakemake.params.tiling)
spill = SpillElevations.load(snakemake.input.spill)
fills = dict(zip(tiling.names(), snakemake.input.fills))


def part(tile):
    log.info("finalising tile %s", tile.name)
    return finalise_tile(TileFill.load(fills[tile.name]), spill)


# the fill takes its values from the surface's cells (max/min, no arithmetic): its dtype is lossless
write_mosaic(snakemake.output.filled, surface, tiling.tiles(shape), part, dtype=dtype)
log.info("filled DEM written from %d tiles (%s)", len(fills), dtype)
