"""Rule change_merge (tiled sites, issue 21): the change products from the tiles."""

from kitegully.change.params import ChangeParams
from kitegully.change.tiles import merge_change
from kitegully.logs import setup_script_logging

log = setup_script_logging(snakemake.log[0])  # noqa: F821
sm = snakemake  # noqa: F821
merge_change(list(sm.input.tiles), sm.input.plan, sm.input.coreg, sm.params.epochs, sm.params.heads_file,
             ChangeParams.from_config(sm.params.methods, seed=sm.params.seed), dict(sm.output), site_crs=sm.params.crs,
             figure=sm.params.figure, attribution=sm.params.attribution, sections_path=sm.params.sections_file)
