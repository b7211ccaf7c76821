"""Rule lowcost_twin: the paper-004 twin (photos, clicks, GPS, tape, tide, panel; truth)."""

from pathlib import Path

from kitegully.logs import setup_script_logging
from kitegully.lowcost import make_lowcost_twin

log = setup_script_logging(snakemake.log[0])
make_lowcost_twin(snakemake.params.twin, snakemake.params.seed, snakemake.params.crs,
                  Path(snakemake.output.observed).parent)
