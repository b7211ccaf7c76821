"""Rule lowcost_survey: joint SfM, tape/Horn/tide georeferencing, mosaics, NDVI, slope, aspect."""

from pathlib import Path

from kitegully.logs import setup_script_logging
from kitegully.lowcost import survey_lowcost

log = setup_script_logging(snakemake.log[0])
survey_lowcost(snakemake.input.observed, snakemake.params.sfm, snakemake.params.survey, snakemake.params.seed,
               snakemake.params.crs, Path(snakemake.output.sfm).parent, threads=snakemake.threads)
