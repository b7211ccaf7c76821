"""Rule dense_tile (tiled sites, issue 21): match one tile of the DSM (its window plus the matcher's halo)."""

from pathlib import Path

from kitegully.dense import DenseParams
from kitegully.dense.tiles import match_dense_tile
from kitegully.logs import setup_script_logging
from kitegully.terrain.tiling import TilingParams

log = setup_script_logging(snakemake.log[0])  # noqa: F821
sm = snakemake  # noqa: F821
match_dense_tile(
    sm.input.model, sm.input.transform, Path(sm.input.sfm_work) / "images", sm.params.crs,
    DenseParams.from_config(sm.params.dense), TilingParams(**sm.params.tiling), sm.wildcards.tile, sm.threads,
    sm.output.tile, site_json=sm.input.get("site"),
)
