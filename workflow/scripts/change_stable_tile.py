"""Rule change_stable_tile (tiled sites, issue 21): stable ground and co-registration candidates of one tile."""

from kitegully.change.params import ChangeParams
from kitegully.change.tiles import stable_tile
from kitegully.logs import setup_script_logging
from kitegully.terrain.tiling import TilingParams

log = setup_script_logging(snakemake.log[0])  # noqa: F821
sm = snakemake  # noqa: F821
stable_tile(sm.params.epochs, sm.params.masks, sm.input.plan, ChangeParams.from_config(sm.params.methods, seed=sm.params.seed),
            TilingParams(**sm.params.tiling), sm.wildcards.tile, sm.output.tile, site_crs=sm.params.crs)
