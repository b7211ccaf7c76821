"""Rule gully_sensitivity: gully area, network and (twin) area scores over σ and the depth threshold."""

from concurrent.futures import ThreadPoolExecutor

import numpy as np

from kitegully.evaluate.network import rasterize_polygons
from kitegully.gully.network import GullyNetwork
from kitegully.gully import GullyParams
from kitegully.gully import gully_sensitivity
from kitegully.io.raster import read_raster
from kitegully.io.tables import write_table
from kitegully.io.vectors import read_vector
from kitegully.logs import setup_script_logging
from kitegully.memory import keep_freed_memory

log = setup_script_logging(snakemake.log[0])
keep_freed_memory()  # whole-DEM temporaries reuse freed heap memory (no page zeroing per array)
inp, crs, sens = snakemake.input, snakemake.params.crs, snakemake.params.sensitivity
with ThreadPoolExecutor(max_workers=1) as pool:  # the two rasters decoded at once (GDAL releases the GIL)
    later = pool.submit(read_raster, inp.depth)  # the stage's own depth map at sigma_m
    dem, grid = read_raster(inp.dem)
    depth, _ = later.result()
reference = read_vector(inp.reference, crs=crs) if getattr(inp, "reference", None) else None
truth = None
if getattr(inp, "truth", None):
    truth = rasterize_polygons(read_vector(inp.truth, crs=crs), grid) & np.isfinite(dem)
table = gully_sensitivity(
    dem, grid, GullyNetwork.load(inp.network_cells), depth, GullyParams.from_config(snakemake.params.mapping),
    sens["sigmas_m"], sens["depth_thresholds_m"], snakemake.params.tolerance_m, reference=reference, truth_mask=truth,
    workers=snakemake.threads,
)
write_table(table, snakemake.output.table, floatfmt=".3g")
