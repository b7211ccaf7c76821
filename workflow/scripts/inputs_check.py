"""Rule check_inputs: every input of the site -> report.md/.json and checked GCP/checkpoint copies (thin adapter)."""

from kitegully.inputs import InputSettings, check_inputs
from kitegully.logs import setup_script_logging

log = setup_script_logging(snakemake.log[0])
check_inputs(
    InputSettings.from_config(snakemake.params.cfg),
    images_dir=snakemake.input.images,
    gcp_file=snakemake.input.gcp,
    checkpoints=snakemake.input.get("checkpoints"),
    out={k: snakemake.output[k] for k in snakemake.output.keys()},
    site=snakemake.params.site,
)
