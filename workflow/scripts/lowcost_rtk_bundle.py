"""Rule lowcost_rtk_bundle: the joint model georeferenced by the GCP bundle on RTK coordinates."""

from pathlib import Path

from kitegully.logs import setup_script_logging
from kitegully.lowcost import adjust_rtk_bundle

log = setup_script_logging(snakemake.log[0])
adjust_rtk_bundle(snakemake.input.observed, Path(snakemake.input.sfm), snakemake.params.georef, snakemake.params.crs,
                  snakemake.params.seed, snakemake.output.folder)
