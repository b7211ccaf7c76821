"""Rule twin_figures: hillshade with gullies, land-cover map, site overview."""

from kitegully.logs import setup_script_logging
from kitegully.twin import figures

log = setup_script_logging(snakemake.log[0])
i, o = snakemake.input, snakemake.output
figures.hillshade_gullies(i.dtm, i.centrelines, o.hillshade, attribution=snakemake.params.attribution)
figures.landcover_map(i.landcover, o.landcover, attribution=snakemake.params.attribution)
figures.site_overview(i.texture, i.targets, i.checkpoints, i.heads, o.overview, attribution=snakemake.params.attribution)
log.info("twin figures written")
