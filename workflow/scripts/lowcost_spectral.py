"""Rule lowcost_spectral: camera responses recovered from a simulated ColorChecker shot."""

from kitegully.logs import setup_script_logging
from kitegully.lowcost import measure_spectral_response

log = setup_script_logging(snakemake.log[0])
measure_spectral_response(snakemake.params.spectral, snakemake.params.seed, snakemake.output.curves,
                          snakemake.output.peaks, snakemake.output.figure)
