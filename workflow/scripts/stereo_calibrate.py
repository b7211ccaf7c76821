"""Rule stereo_calibrate: Table 1, the calibration test and the calibrated cameras."""

from kitegully.logs import setup_script_logging
from kitegully.stereo import calibrate_rig

log = setup_script_logging(snakemake.log[0])  # noqa: F821
sm = snakemake  # noqa: F821
calibrate_rig(sm.params.stereo, sm.params.seed, dict(sm.output))
