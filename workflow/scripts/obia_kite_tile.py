"""Rule obia_kite_tile (tiled sites, issue 21): segment and classify one tile's blocks with the global threshold."""

from kitegully.logs import setup_script_logging
from kitegully.obia.kite_tiles import kite_map_tile
from kitegully.obia.scene import ObiaParams
from kitegully.terrain.tiling import TilingParams

log = setup_script_logging(snakemake.log[0])  # noqa: F821
sm = snakemake  # noqa: F821
kite_map_tile(sm.input.orthophoto, sm.input.dsm, list(sm.input.hists), sm.output.tile, ObiaParams.from_config(sm.params.obia),
              int(sm.params.tile_cells), TilingParams(**sm.params.tiling), sm.wildcards.tile)
