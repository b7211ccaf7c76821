"""Rule gully_standin_dem: the twin's truth DTM plus seeded correlated noise (NOT a photogrammetric DSM)."""

from kitegully.gully.inputs import check_dem
from kitegully.gully.standin import noisy_dem
from kitegully.io.raster import read_raster, write_raster
from kitegully.logs import setup_script_logging

log = setup_script_logging(snakemake.log[0])
noise = snakemake.params.noise
dtm, grid = read_raster(snakemake.input.dtm)
check_dem(dtm, snakemake.input.dtm)
dem = noisy_dem(dtm, grid.cell, noise["noise_sd_m"], noise["noise_correlation_m"], snakemake.params.seed)
write_raster(
    snakemake.output.dem, dem, grid,
    tags={"SOURCE": "truth DTM + noise: evaluation stand-in, NOT the photogrammetric DSM"},
)
log.warning(
    "gully stand-in DEM = twin truth DTM + correlated noise (SD %.3g m, correlation %.3g m): this is an evaluation "
    "stand-in, NOT the photogrammetric DSM; gully.dem: dense maps the dense-matching DSM",
    noise["noise_sd_m"], noise["noise_correlation_m"],
)
