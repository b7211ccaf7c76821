"""Rule validate_truth (twin only): DSM − truth by land cover and the gully profile (Table 5)."""

from kitegully.evaluate.dem import run_truth_validation
from kitegully.logs import setup_script_logging

log = setup_script_logging(snakemake.log[0])  # noqa: F821
sm = snakemake  # noqa: F821
run_truth_validation(
    sm.input.dsm, sm.input.truth_dsm, sm.input.truth_dtm, sm.input.landcover, sm.input.classes,
    sm.input.centrelines, sm.params.validate, dict(sm.output),
)
