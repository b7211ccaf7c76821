"""Rule stereo_dry_box: MAE vs L over the 11 set-ups and the 16 removals."""

from kitegully.logs import setup_script_logging
from kitegully.stereo import measure_dry_box

log = setup_script_logging(snakemake.log[0])  # noqa: F821
sm = snakemake  # noqa: F821
measure_dry_box(sm.params.stereo, sm.input.cameras, sm.params.seed, dict(sm.output))
