"""Rule lowcost_bare_soil: OBIA bare-soil maps of the mosaics by NDVI and by ExG."""

from pathlib import Path

from kitegully.logs import setup_script_logging
from kitegully.lowcost import map_bare_soil

log = setup_script_logging(snakemake.log[0])
inp = snakemake.input
map_bare_soil(inp.rgb, inp.nir, inp.dsm, snakemake.params.bare_soil, Path(snakemake.output.thresholds).parent)
