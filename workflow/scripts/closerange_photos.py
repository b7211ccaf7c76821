"""Rule closerange_photos: render the pole-camera walk of one scene (twin side)."""

import json

import pandas as pd

from kitegully.closerange import photograph_scene
from kitegully.logs import setup_script_logging

log = setup_script_logging(snakemake.log[0])
inp, out, par = snakemake.input, snakemake.output, snakemake.params
scene = snakemake.wildcards.scene
with open(inp.truth_meta, encoding="utf-8") as fh:
    meta = json.load(fh)
truth = photograph_scene(inp.orthophoto, inp.dem, inp.truth_markers, inp.truth_eroded, meta, pd.read_csv(inp.markers),
                         par.walk, float(par.sphere_radius_m), scene not in par.no_rule, par.seed, scene, out.photos)
with open(out.truth, "w", encoding="utf-8") as fh:
    json.dump(truth, fh, indent=1)
