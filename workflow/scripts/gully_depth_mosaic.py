"""Rule gully_depth_mosaic: the depth tiles merged into the smoothed DEM and the depth map."""

import numpy as np
import rasterio

from kitegully.logs import setup_script_logging
from kitegully.terrain.tiling import TilingParams, write_mosaic

log = setup_script_logging(snakemake.log[0])
dem, out = snakemake.input.dem, snakemake.output
with rasterio.open(dem) as src:
    shape = (src.height, src.width)
tiling = TilingParams(**snakemake.params.tiling)
paths = dict(zip(tiling.names(), snakemake.input.tiles))
for key in ("smoothed", "depth"):
    write_mosaic(out[key], dem, tiling.tiles(shape), lambda t: np.load(paths[t.name])[key], dtype="float32")
log.info("depth map merged from %d tiles", len(paths))
