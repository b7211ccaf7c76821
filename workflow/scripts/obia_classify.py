"""Rule obia_classify: classify one scene (orthophoto + DEM) into grass / eroded by ExG and OBIA."""

import json

import pandas as pd

from kitegully.io.raster import read_raster, write_raster
from kitegully.io.vectors import write_vector
from kitegully.logs import setup_script_logging
from kitegully.obia import classify_scene_products

log = setup_script_logging(snakemake.log[0])
inp, out = snakemake.input, snakemake.output
rgb, grid = read_raster(inp.orthophoto, band=None)
dem, dgrid = read_raster(inp.dem)
sc = classify_scene_products(rgb, dem, grid, dgrid, pd.read_csv(inp.markers), snakemake.params.obia,
                             snakemake.wildcards.scene,
                             {"orthophoto": inp.orthophoto, "dem": inp.dem, "markers": inp.markers})
res = sc.result
write_raster(out.segments, res.segments, grid, nodata=0, band_names=["segment id"])
write_raster(out.exg, res.exg_blur, grid, band_names=["ExG, Gaussian-blurred"])
write_raster(out.classification, res.classes, grid, nodata=255, band_names=["eroded (1) / grass (0)"])
write_raster(out.classification_otsu, res.classes_otsu, grid, nodata=255, band_names=["eroded (1) / grass (0), Otsu"])
write_vector(sc.polygons, out.polygons)
sc.histogram.to_csv(out.histogram, index=False)
with open(out.info, "w", encoding="utf-8") as fh:
    json.dump(sc.info, fh, indent=2)
