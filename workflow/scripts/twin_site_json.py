"""Rule twin_site_json: what a planner knows about the twin site (extent, CRS, cells)."""

from kitegully.logs import setup_script_logging
from kitegully.twin import TwinParams, build_site, write_site_json

log = setup_script_logging(snakemake.log[0])
site = build_site(TwinParams.from_config(snakemake.params.twin), snakemake.params.crs, snakemake.params.seed, epoch=1)
write_site_json(site, snakemake.output.site)
log.info("site.json written: %s", snakemake.output.site)
