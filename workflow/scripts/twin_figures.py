"""Rule twin_figures: hillshade with gullies, land-cover map, site overview."""

from kitegully.logs import setup_script_logging
from kitegully.twin.figures import twin_figures

log = setup_script_logging(snakemake.log[0])
i, o = snakemake.input, snakemake.output
twin_figures(i.dtm, i.centrelines, i.landcover, i.texture, i.targets, i.checkpoints, i.heads,
             o.hillshade, o.landcover, o.overview, attribution=snakemake.params.attribution)
log.info("twin figures written")
