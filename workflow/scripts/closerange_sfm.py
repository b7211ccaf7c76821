"""Rule closerange_sfm: photos + sphere survey -> SfM model, 2 cm DEM and orthophoto, Table 1 record."""

import json

import pandas as pd

from kitegully.closerange import CloseRangeParams, photogrammetric_orthophoto
from kitegully.io.raster import read_raster
from kitegully.logs import setup_script_logging

log = setup_script_logging(snakemake.log[0])
inp, out = snakemake.input, snakemake.output
_, grid = read_raster(inp.frame)  # the scene's mapping frame (extent, 2 cm cells)
params = CloseRangeParams.from_config(snakemake.params.closerange)
paths = {k: out[k] for k in ("model", "summary", "images", "image_info", "orthophoto", "dem", "spheres")}
record = photogrammetric_orthophoto(inp.photos, pd.read_csv(inp.markers), inp.markers, grid, snakemake.params.sfm, params,
                                    snakemake.params.seed, snakemake.threads, snakemake.wildcards.scene, out.work, paths)
with open(out.record, "w", encoding="utf-8") as fh:
    json.dump(record, fh, indent=1)
