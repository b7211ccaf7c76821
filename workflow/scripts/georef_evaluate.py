"""Rule georef_evaluate (twin sites only): camera positions and GCP residuals against the flight truth."""

import json

import pandas as pd

from kitegully.georef.evaluate import evaluate_twin
from kitegully.georef.export import clean_json
from kitegully.io.tables import write_table
from kitegully.io.vectors import read_vector
from kitegully.logs import setup_script_logging

log = setup_script_logging(snakemake.log[0])
cams = read_vector(snakemake.input.cameras)
truth = pd.read_csv(snakemake.input.poses)
stats = pd.read_csv(snakemake.input.image_stats)
gsd = float(stats["gsd_m"].median())
sfm = json.loads(open(snakemake.input.sfm_summary, encoding="utf-8").read())
table, summary = evaluate_twin(
    pd.DataFrame(cams.drop(columns="geometry")), truth, pd.read_csv(snakemake.input.residuals),
    pd.read_csv(snakemake.input.loo), gsd, sfm["n_images"],
)
write_table(table, snakemake.output.table)
with open(snakemake.output.summary, "w", encoding="utf-8") as fh:
    json.dump(clean_json(summary), fh, indent=2)
log.info("twin evaluation: %s", summary["targets"])
