"""Rule ortho_plan (tiled sites, issue 21): fill the merged DSM's holes and pick the finest pyramid level once."""

from pathlib import Path

from kitegully.dense import DenseParams
from kitegully.dense.ortho_tiles import load_views, plan_orthophoto
from kitegully.logs import setup_script_logging

log = setup_script_logging(snakemake.log[0])  # noqa: F821
sm = snakemake  # noqa: F821
views = load_views(sm.input.model, sm.input.transform, Path(sm.input.sfm_work) / "images")
plan_orthophoto(views, sm.input.dsm, DenseParams.from_config(sm.params.dense), sm.output.filled, sm.output.plan)
