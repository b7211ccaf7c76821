"""Rule closerange_sfm: photos + sphere survey -> SfM model, 2 cm DEM and orthophoto, Table 1 record.

With ``closerange.on_scene_failure: record`` (``make closerange``) a scene that cannot be
georeferenced logs its one sentence as the last log line, writes it as its record
(status ``failed``) and leaves the other outputs as empty markers; the summary skips it.
"""

import json
from pathlib import Path

import pandas as pd

from kitegully import InputError
from kitegully.closerange import CloseRangeParams, failed_scene_record, photogrammetric_orthophoto
from kitegully.io.raster import read_raster
from kitegully.logs import setup_script_logging

log = setup_script_logging(snakemake.log[0])
inp, out, scene = snakemake.input, snakemake.output, snakemake.wildcards.scene
_, grid = read_raster(inp.frame)  # the scene's mapping frame (extent, 2 cm cells)
params = CloseRangeParams.from_config(snakemake.params.closerange)
paths = {k: out[k] for k in ("model", "summary", "images", "image_info", "orthophoto", "dem", "spheres")}
try:
    record = photogrammetric_orthophoto(inp.photos, pd.read_csv(inp.markers), inp.markers, grid, snakemake.params.sfm, params,
                                        snakemake.params.seed, snakemake.threads, scene, out.work, paths)
except InputError as err:
    if params.on_scene_failure != "record":
        raise
    record = failed_scene_record(scene, str(err))
    for key in ("model", "work"):
        Path(out[key]).mkdir(parents=True, exist_ok=True)
    for key in ("summary", "images", "image_info", "orthophoto", "dem", "spheres"):
        Path(out[key]).write_bytes(b"")  # empty marker: the summary does not read a failed scene's products
    log.error("%s failed (recorded, closerange.on_scene_failure: record): %s", scene, err)
with open(out.record, "w", encoding="utf-8") as fh:
    json.dump(record, fh, indent=1)
