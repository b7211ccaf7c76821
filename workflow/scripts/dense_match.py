"""Rule dense_match: georeferenced model → DSM, correlation, orthophoto, shading, summary."""

from pathlib import Path

from kitegully.dense.stage import run_dense_stage
from kitegully.logs import setup_script_logging

log = setup_script_logging(snakemake.log[0])  # noqa: F821
sm = snakemake  # noqa: F821
run_dense_stage(
    sm.input.model, sm.input.transform, Path(sm.input.sfm_work) / "images", sm.params.crs, sm.params.dense,
    sm.threads, dict(sm.output), site_json=sm.input.get("site"),
)
