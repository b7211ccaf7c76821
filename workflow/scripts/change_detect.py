"""Rule change_detect: two epoch DEMs -> DoD, thresholds, budgets, headcut retreat (issue 17)."""

from kitegully.change.params import ChangeParams
from kitegully.change.stage import detect_change
from kitegully.logs import setup_script_logging

log = setup_script_logging(snakemake.log[0])  # noqa: F821
sm = snakemake  # noqa: F821
detect_change(
    sm.params.epochs, sm.params.masks, sm.params.heads_file,
    ChangeParams.from_config(sm.params.methods, seed=sm.params.seed), dict(sm.output),
    site_crs=sm.params.crs, figure=sm.params.figure, attribution=sm.params.attribution,
    sections_path=sm.params.sections_file,
)
