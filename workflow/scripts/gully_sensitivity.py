"""Rule gully_sensitivity: gully area, network and (twin) area scores over σ and the depth threshold."""

import numpy as np

from kitegully.evaluate.network import footprint, rasterize_polygons
from kitegully.gully.network import GullyNetwork, network_lines
from kitegully.gully.sensitivity import sensitivity_table
from kitegully.io.raster import read_raster
from kitegully.io.tables import write_table
from kitegully.io.vectors import read_vector
from kitegully.logs import setup_script_logging

log = setup_script_logging(snakemake.log[0])
cfg = snakemake.params.cfg
crs = snakemake.params.crs
dem, grid = read_raster(snakemake.input.dem)
net = GullyNetwork.load(snakemake.input.network_cells)
depth, _ = read_raster(snakemake.input.depth)  # the stage's own depth map at sigma_m
reference = read_vector(snakemake.input.reference, crs=crs) if getattr(snakemake.input, "reference", None) else None
truth = None
if getattr(snakemake.input, "truth", None):
    truth = rasterize_polygons(read_vector(snakemake.input.truth, crs=crs), grid) & np.isfinite(dem)
table = sensitivity_table(
    dem, grid, net, cfg["sensitivity"]["sigmas_m"], cfg["sensitivity"]["depth_thresholds_m"],
    cfg["min_patch_volume_m3"], cfg["buffer_m"], cfg["connectivity"], cfg["truncate_sigmas"],
    reference=reference, tolerance_m=cfg["validation"]["tolerance_m"],
    # DEM footprint near the lines only: same clipping as the whole footprint, far cheaper
    domain=footprint(np.isfinite(dem), grid, near=[*reference.geometry, *network_lines(net, grid).geometry])
    if reference is not None else None,
    truth_mask=truth, workers=snakemake.threads, known_depths={float(cfg["sigma_m"]): depth},
)
write_table(table, snakemake.output.table, floatfmt=".3g")
