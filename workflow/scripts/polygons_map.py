"""Rule polygons_map: DEM prep, breaklines, thalweg, dams, fill depth, polygons, medial axes, cross-sections."""

from kitegully import InputError
from kitegully.io.raster import Raster
from kitegully.io.tables import write_table
from kitegully.io.vectors import write_vector
from kitegully.logs import setup_script_logging
from kitegully.polygons.stage import PolygonParams, measure_polygons

log = setup_script_logging(snakemake.log[0])
out = snakemake.output
dem = Raster.read(snakemake.input.dem)
if dem.crs != snakemake.params.crs:
    raise InputError(f"{snakemake.input.dem}: CRS {dem.crs} does not match the site CRS {snakemake.params.crs}")
params = PolygonParams.from_config(snakemake.params.cfg)
res = measure_polygons(dem.data, dem.grid, params, dem_name=snakemake.input.dem, morphometry=snakemake.params.morphometry)

for path, (t, gdf) in zip(out.polygons, sorted(res.polygons.items())):
    write_vector(gdf, path, layer="gully_polygons")
for name, arr in (("dem", res.dem), ("tci", res.tci), ("fill_depth", res.fill_depth)):
    Raster(arr.astype("float32"), res.grid).write(out[name])
for name in ("breaklines", "thalweg", "transects"):
    write_vector(getattr(res, name), out[name])
if snakemake.params.morphometry:
    write_vector(res.axes, out.axes, layer="medial_axes")
    write_vector(res.sections, out.sections, layer="cross_sections")
    write_table(res.morphometry, out.morphometry)
else:  # tiled site: the polygons_morph_tile jobs measure the polygons in windows of these rasters
    Raster(res.labels[params.morph_threshold_m], res.grid).write(out.labels)
    Raster(res.level.astype("float32"), res.grid).write(out.level)
    Raster(res.rims.astype("uint8"), res.grid).write(out.rims)
write_table(res.summary, out.summary)
