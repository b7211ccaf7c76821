"""Rule check_dem_file: a DEM GeoTIFF the site hands to a DEM stage (gully.dem_file, polygons.dem_file), checked.

Writes the checked copy (float32, NaN = nodata, the site CRS) that the stage's rules read.
"""

from kitegully.inputs.rasters import read_dem_file
from kitegully.io.raster import write_raster
from kitegully.logs import setup_script_logging

log = setup_script_logging(snakemake.log[0])
p = snakemake.params
dem, grid = read_dem_file(snakemake.input.dem, p.crs, p.nodata, p.key)
write_raster(snakemake.output.dem, dem, grid, tags={"SOURCE": f"{snakemake.input.dem} (checked; {p.key})"})
log.info("%s: %d x %d cells of %.3g m, %.1f %% valid, elevations %.2f to %.2f m", snakemake.input.dem, grid.width, grid.height,
         grid.cell, 100.0 * float((dem == dem).mean()), float(dem[dem == dem].min()), float(dem[dem == dem].max()))
