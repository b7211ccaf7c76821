"""Rule gully_section: Fig. 4 style section view across the deepest mapped gully cell."""

from kitegully.gully.network import GullyNetwork
from kitegully.gully.plots import pick_section, section_figure
from kitegully.io.figures import save_figure
from kitegully.io.raster import read_raster
from kitegully.logs import setup_script_logging

log = setup_script_logging(snakemake.log[0])
p = snakemake.params
dem, grid = read_raster(snakemake.input.dem)
smoothed, _ = read_raster(snakemake.input.smoothed)
depth, _ = read_raster(snakemake.input.depth)
gully, _ = read_raster(snakemake.input.gully_map)
net = GullyNetwork.load(snakemake.input.network_cells)
line = pick_section(net, depth, gully == 1, grid, p.half_length_m)
log.info("section from (%.1f, %.1f) to (%.1f, %.1f)", *line)
fig = section_figure(dem, smoothed, depth, gully == 1, grid, line, p.sigma_m, p.depth_threshold_m)
save_figure(fig, snakemake.output.figure, attribution=p.attribution)
