"""Rule polygons_crowns: the site's crown mask on the dense DSM (``polygons.gap_fill.crowns``).

The gully stage's definition (``gully.crowns``, ``gully.automatic_heads``): plants the
orthophoto shows standing above the ground, widened by the matching window. The polygons
stage empties these DSM cells and fills them by moving planes from the ground around them.
"""

import numpy as np

from kitegully.gully.inputs import check_dem
from kitegully.gully.pipeline import site_crown_mask
from kitegully.io.raster import read_raster, write_raster
from kitegully.logs import setup_script_logging

log = setup_script_logging(snakemake.log[0])
inp, par = snakemake.input, snakemake.params
dem, grid = read_raster(inp.dem)
check_dem(dem, inp.dem, grid.crs, par.crs)
mask = site_crown_mask(np.asarray(dem, dtype=np.float32), grid, par.mapping, par.heads, par.automatic_heads, inp.ortho,
                       inp.get("checkpoints"), snakemake.threads)
write_raster(snakemake.output.crowns, mask.astype(np.uint8), grid)
log.info("crown mask: %d of %d valid DSM cells (%.1f %%)", int(mask.sum()), int(np.isfinite(dem).sum()),
         100.0 * mask.sum() / max(1, int(np.isfinite(dem).sum())))
