"""Rule dense_match: georeferenced model → DSM, correlation, orthophoto, shading, summary."""

from pathlib import Path

from kitegully.dense import DenseParams, match_dense_surface
from kitegully.dense.datum import used_gcps
from kitegully.logs import setup_script_logging

log = setup_script_logging(snakemake.log[0])  # noqa: F821
sm = snakemake  # noqa: F821
gcps = None
if "gcp" in sm.input.keys():  # dense.datum enabled: the targets the GCP adjustment used
    gcps = used_gcps(sm.input.gcp, sm.input.gcp_residuals, sm.params.crs, sm.params.gcp_format, sm.params.csv_crs)
match_dense_surface(
    sm.input.model, sm.input.transform, Path(sm.input.sfm_work) / "images", sm.params.crs,
    DenseParams.from_config(sm.params.dense), sm.threads, dict(sm.output), site_json=sm.input.get("site"), gcps=gcps,
)
