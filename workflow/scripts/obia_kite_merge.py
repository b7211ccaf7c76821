"""Rule obia_kite_merge (tiled sites, issue 21): the tiles' classes into the bare-soil map, polygons, record, figure."""

from kitegully.logs import setup_script_logging
from kitegully.obia.kite_tiles import finish_kite_map
from kitegully.obia.scene import ObiaParams

log = setup_script_logging(snakemake.log[0])  # noqa: F821
sm = snakemake  # noqa: F821
finish_kite_map(list(sm.input.tiles), list(sm.input.hists), sm.input.orthophoto, ObiaParams.from_config(sm.params.obia),
                dict(sm.output), float(sm.params.figure_max_px), sm.params.attribution)
