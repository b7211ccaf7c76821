"""Rule ortho_merge (tiled sites, issue 21): the orthophoto COG from the tile jobs, window by window."""

from kitegully.dense.ortho_tiles import merge_ortho_tiles
from kitegully.logs import setup_script_logging

log = setup_script_logging(snakemake.log[0])  # noqa: F821
sm = snakemake  # noqa: F821
merge_ortho_tiles(list(sm.input.tiles), sm.input.dsm, sm.output.orthophoto, sm.output.stats)
