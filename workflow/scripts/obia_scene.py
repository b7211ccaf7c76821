"""Generate one synthetic close-range scene (twin): orthophoto, DEM, markers, truth."""

import json

from kitegully.io.raster import write_raster
from kitegully.logs import setup_script_logging
from kitegully.twin.closerange import generate_scene, scene_names, scene_origin

log = setup_script_logging(snakemake.log[0])
params = snakemake.params.scenes
name = snakemake.wildcards.scene
index = scene_names(len(params["list"])).index(name)
scene = generate_scene(name, params, params["list"][index], snakemake.params.seed, snakemake.params.crs, scene_origin(index, params))
out = snakemake.output
write_raster(out.orthophoto, scene.rgb, scene.grid, nodata=None, band_names=["red", "green", "blue"])
write_raster(out.dem, scene.dem, scene.grid)
scene.markers.to_csv(out.markers, index=False, float_format="%.4f")
write_raster(out.truth_eroded, scene.truth_eroded, scene.grid, nodata=255, band_names=["eroded (1) / grass (0)"])
write_raster(out.truth_markers, scene.truth_markers, scene.grid, nodata=255, band_names=["GCP sphere (1)"])
with open(out.truth_meta, "w", encoding="utf-8") as fh:
    json.dump(scene.meta, fh, indent=2)
log.info("%s: %s", name, scene.meta)
