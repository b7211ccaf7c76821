"""Rule tether_plan: flight plan per strip and the line lengths the model needs per material."""

from kitegully.io.tables import write_table
from kitegully.logs import setup_script_logging
from kitegully.tether import TetherParams, plan_flights

log = setup_script_logging(snakemake.log[0])
plan, lengths = plan_flights(TetherParams.from_config(snakemake.params.tether))
write_table(plan, snakemake.output.plan)
write_table(lengths, snakemake.output.lengths)
