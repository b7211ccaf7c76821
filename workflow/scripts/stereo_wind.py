"""Rule stereo_wind: the sand tray before and after the wind."""

from kitegully.logs import setup_script_logging
from kitegully.stereo import measure_wind

log = setup_script_logging(snakemake.log[0])  # noqa: F821
sm = snakemake  # noqa: F821
measure_wind(sm.params.stereo, sm.input.cameras, sm.params.seed, dict(sm.output))
