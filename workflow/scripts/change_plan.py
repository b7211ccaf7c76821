"""Rule change_plan (tiled sites, issue 21): whole-grid numbers of the tiled change stage."""

from kitegully.change.params import ChangeParams
from kitegully.change.tiles import plan_change
from kitegully.logs import setup_script_logging

log = setup_script_logging(snakemake.log[0])  # noqa: F821
sm = snakemake  # noqa: F821
plan_change(sm.params.epochs, sm.output.plan, site_crs=sm.params.crs,
            checkpoint_outlier_nmad=ChangeParams.from_config(sm.params.methods).checkpoint_outlier_nmad)
