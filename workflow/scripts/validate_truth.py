"""Rule validate_truth (twin only): DSM − truth by land cover and the gully profile (Table 5)."""

from kitegully.evaluate import TruthParams, validate_against_truth
from kitegully.logs import setup_script_logging

log = setup_script_logging(snakemake.log[0])  # noqa: F821
sm = snakemake  # noqa: F821
validate_against_truth(
    sm.input.dsm, sm.input.truth_dsm, sm.input.truth_dtm, sm.input.landcover, sm.input.classes,
    sm.input.centrelines, TruthParams.from_config(sm.params.validate), dict(sm.output),
)
