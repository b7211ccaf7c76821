"""Rule lowcost_evaluate: NDVI per class, bare-ground indicators, georeferencing vs the twin's truth."""

from pathlib import Path

from kitegully.logs import setup_script_logging
from kitegully.lowcost import evaluate_lowcost

log = setup_script_logging(snakemake.log[0])
evaluate_lowcost(Path(snakemake.output.summary).parent, snakemake.input.truth, snakemake.params.evaluation,
                 snakemake.params.seed, Path(snakemake.output.summary).parent)
