"""Rule polygons_morph_merge: the tiles' medial axes, cross-sections and morphometry joined; the stage summary."""

import pandas as pd

from kitegully.io.tables import write_table
from kitegully.io.vectors import write_vector
from kitegully.logs import setup_script_logging
from kitegully.polygons.stage import PolygonParams
from kitegully.polygons.tiles import merge_morphometry, merged_summary

log = setup_script_logging(snakemake.log[0])
out = snakemake.output
parts = [pd.read_pickle(p) for p in snakemake.input.parts]
axes, sections, morph = merge_morphometry([(d["axes"], d["sections"], d["morphometry"]) for d in parts], snakemake.params.crs)
summary_map = pd.read_csv(snakemake.input.summary, dtype={"quantity": str, "value": str}, keep_default_na=False)
summary = merged_summary(summary_map, axes, sections, morph, PolygonParams.from_config(snakemake.params.cfg),
                         sum(d["seconds"] for d in parts), len(parts))
write_vector(axes, out.axes, layer="medial_axes")
write_vector(sections, out.sections, layer="cross_sections")
write_table(morph, out.morphometry)
write_table(summary, out.summary)
log.info("morphometry merged from %d tiles: %d polygons, %d sections", len(parts), len(morph), len(sections))
