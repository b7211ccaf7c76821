"""Rule georef_evaluate (twin sites only): camera positions and GCP residuals against the flight truth."""

from kitegully.georef.evaluate import evaluate_against_flight_truth
from kitegully.logs import setup_script_logging

log = setup_script_logging(snakemake.log[0])
i, o = snakemake.input, snakemake.output
summary = evaluate_against_flight_truth(i.cameras, i.poses, i.image_stats, i.residuals, i.loo, i.sfm_summary,
                                        o.table, o.summary)
log.info("twin evaluation: %s", summary["targets"])
