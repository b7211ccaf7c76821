"""Rule change_tile (tiled sites, issue 21): DoD, sigma, thresholds and partial budget sums of one tile."""

from kitegully.change.params import ChangeParams
from kitegully.change.tiles import change_tile
from kitegully.logs import setup_script_logging
from kitegully.terrain.tiling import TilingParams

log = setup_script_logging(snakemake.log[0])  # noqa: F821
sm = snakemake  # noqa: F821
change_tile(sm.params.epochs, sm.params.masks, sm.input.plan, sm.input.coreg, sm.input.stable,
            ChangeParams.from_config(sm.params.methods, seed=sm.params.seed), TilingParams(**sm.params.tiling),
            sm.wildcards.tile, sm.output.tile, site_crs=sm.params.crs)
