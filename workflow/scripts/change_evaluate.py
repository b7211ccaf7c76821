"""Rule change_evaluate: DoD, budgets and headcuts against the known change (evaluation only)."""

from kitegully.change.evaluation import evaluate_change
from kitegully.change.params import THRESHOLD_METHODS, ChangeParams
from kitegully.logs import setup_script_logging

log = setup_script_logging(snakemake.log[0])  # noqa: F821
sm = snakemake  # noqa: F821
evaluate_change(
    sm.input.dod, sm.input.sigma_dod, {m: sm.input[f"thresholded_{m}"] for m in THRESHOLD_METHODS},
    sm.input.truth1, sm.input.truth2, sm.params.masks, sm.input.budget, sm.input.headcuts,
    sm.input.get("heads1_truth"), sm.input.get("heads2_truth"), sm.params.evaluation, dict(sm.output),
    widening=(sm.input.widening, sm.input.get("polygons1_truth"), sm.input.get("polygons2_truth"),
              sm.params.widening_margin_m, sm.input.get("sections")),
    headcut_ceiling=((sm.input.heads, ChangeParams.from_config(sm.params.methods, seed=sm.params.seed))
                     if sm.input.get("heads") else None),
)
