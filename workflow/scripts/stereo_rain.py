"""Rule stereo_rain: the three bulk densities under simulated rain."""

from kitegully.logs import setup_script_logging
from kitegully.stereo import measure_rain

log = setup_script_logging(snakemake.log[0])  # noqa: F821
sm = snakemake  # noqa: F821
measure_rain(sm.params.stereo, sm.input.cameras, sm.params.seed, dict(sm.output))
