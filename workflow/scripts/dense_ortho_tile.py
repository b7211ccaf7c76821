"""Rule ortho_tile (tiled sites, issue 21): render one orthophoto tile of whole rendering blocks."""

from pathlib import Path

import numba

from kitegully.dense import DenseParams
from kitegully.dense.ortho_tiles import load_views, render_ortho_tile
from kitegully.logs import setup_script_logging
from kitegully.terrain.tiling import TilingParams

log = setup_script_logging(snakemake.log[0])  # noqa: F821
sm = snakemake  # noqa: F821
numba.set_num_threads(max(1, min(int(sm.threads), numba.config.NUMBA_NUM_THREADS)))
views = load_views(sm.input.model, sm.input.transform, Path(sm.input.sfm_work) / "images")
render_ortho_tile(views, sm.input.filled, sm.input.plan, DenseParams.from_config(sm.params.dense),
                  TilingParams(**sm.params.tiling), sm.wildcards.tile, sm.output.tile)
