"""Classify one scene (orthophoto + DEM) into grass / eroded by ExG and OBIA."""

import json

import numpy as np
import pandas as pd

from kitegully import InputError
from kitegully.io.raster import read_raster, write_raster
from kitegully.io.vectors import write_vector
from kitegully.logs import setup_script_logging
from kitegully.obia.classify import eroded_polygons
from kitegully.obia.scene import ObiaParams, classify_scene, marker_mask

log = setup_script_logging(snakemake.log[0])
inp, out = snakemake.input, snakemake.output
cfg = snakemake.params.obia
params = ObiaParams.from_config(cfg)
rgb, grid = read_raster(inp.orthophoto, band=None)
dem, dgrid = read_raster(inp.dem)
if dgrid != grid:
    raise InputError(f"{inp.dem}: DEM grid {dgrid} differs from the orthophoto grid {grid}")
markers = pd.read_csv(inp.markers)
missing = {"x", "y", "radius_m"} - set(markers.columns)
if missing:
    raise InputError(f"{inp.markers}: missing columns {sorted(missing)}")
masked = marker_mask(dem.shape, grid, markers, float(cfg["classification"]["marker_mask_factor"]))
res = classify_scene(rgb, dem, grid.cell, params, valid=~masked, source=str(inp.orthophoto))

write_raster(out.segments, res.segments, grid, nodata=0, band_names=["segment id"])
write_raster(out.exg, res.exg_blur, grid, band_names=["ExG, Gaussian-blurred"])
write_raster(out.classification, res.classes, grid, nodata=255, band_names=["eroded (1) / grass (0)"])
write_raster(out.classification_otsu, res.classes_otsu, grid, nodata=255, band_names=["eroded (1) / grass (0), Otsu"])
write_vector(eroded_polygons(res.classes, grid.transform, grid.crs, snakemake.wildcards.scene), out.polygons)
thr = res.threshold
pd.DataFrame({"exg": thr.centres, "count": thr.counts}).to_csv(out.histogram, index=False)
info = {
    "scene": snakemake.wildcards.scene,
    **thr.as_dict(),
    "n_seeds": int(res.seeds.max()),
    "n_segments": int(res.n_segments),
    "masked_cells": int(masked.sum()),
    "area_auto_m2": float(np.sum(res.classes == 1) * grid.cell ** 2),
    "area_auto_otsu_m2": float(np.sum(res.classes_otsu == 1) * grid.cell ** 2),
    "timings_s": res.timings_s,
}
if not thr.bimodal:
    log.warning("%s: ExG histogram is not bimodal (%s); every segment is %s", inp.orthophoto, thr.reason, params.unimodal_class)
with open(out.info, "w", encoding="utf-8") as fh:
    json.dump(info, fh, indent=2)
