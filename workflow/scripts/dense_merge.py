"""Rule dense_merge (tiled sites, issue 21): DSM and correlation mosaics window by window, datum check."""

from kitegully.dense import DenseParams
from kitegully.dense.datum import used_gcps
from kitegully.dense.tiles import merge_dense_tiles
from kitegully.logs import setup_script_logging

log = setup_script_logging(snakemake.log[0])  # noqa: F821
sm = snakemake  # noqa: F821
gcps = None
if "gcp" in sm.input.keys():  # dense.datum enabled: the targets the GCP adjustment used
    gcps = used_gcps(sm.input.gcp, sm.input.gcp_residuals, sm.params.crs, sm.params.gcp_format, sm.params.csv_crs)
merge_dense_tiles(list(sm.input.tiles), DenseParams.from_config(sm.params.dense), dict(sm.output), gcps=gcps)
