"""Rule polygons_morph_tile: medial axes, cross-sections and morphometry of the polygons one tile owns."""

import time

import pandas as pd
import rasterio

from kitegully.io.raster import grid_of
from kitegully.io.vectors import read_vector
from kitegully.logs import setup_script_logging
from kitegully.polygons.stage import PolygonParams
from kitegully.polygons.tiles import measure_tile, read_window
from kitegully.terrain.tiling import TilingParams

log = setup_script_logging(snakemake.log[0])
inp = snakemake.input
with rasterio.open(inp.labels) as src:
    grid = grid_of(src, inp.labels)
tiling = TilingParams(**snakemake.params.tiling)
tile = tiling.tile(grid.shape, snakemake.wildcards.tile)
t0 = time.perf_counter()
axes, sections, morph = measure_tile(read_vector(inp.polygons), grid, tile, lambda name, *win: read_window(inp[name], *win),
                                     PolygonParams.from_config(snakemake.params.cfg), tiling.tiles(grid.shape))
seconds = time.perf_counter() - t0
pd.to_pickle({"axes": axes, "sections": sections, "morphometry": morph, "seconds": seconds}, snakemake.output.part)
log.info("tile %s: %d polygons, %d sections in %.1f s", tile.name, len(morph), len(sections), seconds)
