"""Rule obia_summary: accuracy tables over all close-range scenes (001 Tables 2-3) and valley vs Otsu."""

import json

from kitegully.io.figures import save_figure
from kitegully.io.tables import write_table
from kitegully.logs import setup_script_logging
from kitegully.obia import summarise_scenes, summary_figure

log = setup_script_logging(snakemake.log[0])
out = snakemake.output
results = []
for path in snakemake.input.confusion:
    with open(path, encoding="utf-8") as fh:
        results.append(json.load(fh))
summary = summarise_scenes(results)
write_table(summary.accuracy, out.accuracy, floatfmt=".1f")
write_table(summary.areas, out.areas, floatfmt=".2f")
write_table(summary.comparison, out.comparison, floatfmt=".3g")
save_figure(summary_figure(summary), out.figure, attribution="synthetic close-range scenes (kitegully twin)")
