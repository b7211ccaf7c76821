"""Rule dense_finish (tiled sites, issue 21): shading and summary from the merged DSM and the tile stats."""

from kitegully.dense import DenseParams
from kitegully.dense.tiles import finish_dense_surface
from kitegully.logs import setup_script_logging

log = setup_script_logging(snakemake.log[0])  # noqa: F821
sm = snakemake  # noqa: F821
finish_dense_surface(sm.input.dsm, sm.input.stats, sm.input.ortho_stats, DenseParams.from_config(sm.params.dense),
                     sm.threads, dict(sm.output))
