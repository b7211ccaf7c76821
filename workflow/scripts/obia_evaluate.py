"""Rule obia_evaluate: one scene against its truth mask: confusion matrices and the scene figure."""

import json

import numpy as np
import pandas as pd

from kitegully.io.figures import save_figure
from kitegully.io.raster import read_raster
from kitegully.logs import setup_script_logging
from kitegully.obia.accuracy import accuracies
from kitegully.obia import evaluate_scene, scene_figure

log = setup_script_logging(snakemake.log[0])
inp, out, scene = snakemake.input, snakemake.output, snakemake.wildcards.scene
rgb, grid = read_raster(inp.orthophoto, band=None)
segments, _ = read_raster(inp.segments)
classes, _ = read_raster(inp.classification)
classes_otsu, _ = read_raster(inp.classification_otsu)
truth, _ = read_raster(inp.truth_eroded)
with open(inp.info, encoding="utf-8") as fh:
    info = json.load(fh)
result = evaluate_scene(classes, classes_otsu, truth, grid.cell, info, scene)
with open(out.confusion, "w", encoding="utf-8") as fh:
    json.dump(result, fh, indent=2)
oa = accuracies(np.asarray(result["confusion"]))["overall"]
fig = scene_figure(rgb, segments, classes, truth, pd.read_csv(inp.histogram), info, grid, scene, oa)
save_figure(fig, out.figure, attribution="synthetic close-range scene (kitegully twin), method after Mayr et al. 2016")
