"""Rule validate_checkpoints: DSM errors at independent checkpoints (Table 3 style)."""

from kitegully.evaluate import CheckpointParams, validate_checkpoints
from kitegully.logs import setup_script_logging

log = setup_script_logging(snakemake.log[0])  # noqa: F821
sm = snakemake  # noqa: F821
validate_checkpoints(
    sm.input.dsm, sm.input.checkpoints, CheckpointParams.from_config(sm.params.validate), dict(sm.output),
    landcover_path=sm.input.get("landcover"), classes_path=sm.input.get("classes"),
)
