"""Rule change_coregister (tiled sites, issue 21): one global co-registration fit on the tiles' stable cells."""

from kitegully.change.params import ChangeParams
from kitegully.change.tiles import coregister_tiles
from kitegully.logs import setup_script_logging

log = setup_script_logging(snakemake.log[0])  # noqa: F821
sm = snakemake  # noqa: F821
coregister_tiles(list(sm.input.tiles), sm.params.epochs, ChangeParams.from_config(sm.params.methods, seed=sm.params.seed),
                 sm.output.coreg, site_crs=sm.params.crs)
