"""Rule obia_kite_histogram (tiled sites, issue 21): fine histogram of one tile's blocks."""

from kitegully.logs import setup_script_logging
from kitegully.obia.kite_tiles import kite_histogram_tile
from kitegully.obia.scene import ObiaParams
from kitegully.terrain.tiling import TilingParams

log = setup_script_logging(snakemake.log[0])  # noqa: F821
sm = snakemake  # noqa: F821
kite_histogram_tile(sm.input.orthophoto, sm.input.dsm, sm.output.hist, ObiaParams.from_config(sm.params.obia),
                    int(sm.params.tile_cells), TilingParams(**sm.params.tiling), sm.wildcards.tile)
