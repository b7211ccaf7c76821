"""Rule gully_fill_merge: pass 2 of the tiled Priority-Flood: spill elevations of every tile's watershed labels."""

from kitegully.logs import setup_script_logging
from kitegully.terrain.tiled_fill import TileSummary, merge_tiles

log = setup_script_logging(snakemake.log[0])
summaries = [TileSummary.load(p) for p in snakemake.input.summaries]
spill = merge_tiles(summaries)
spill.save(snakemake.output.spill)
log.info("merged %d tiles: %d watershed labels", len(summaries), spill.spill.size - 1)
