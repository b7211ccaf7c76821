"""Snakemake adapter: the peat-valley DEM twin (kitegully.twin.peat_valley)."""

from kitegully.io.vectors import write_vector
from kitegully.logs import setup_script_logging
from kitegully.twin.peat_valley import PeatValleyParams, make_peat_valley

log = setup_script_logging(snakemake.log[0])
site = make_peat_valley(PeatValleyParams.from_config(snakemake.params.cfg), snakemake.params.seed, snakemake.params.crs)
site.observed.write(snakemake.output.dtm)
site.truth.write(snakemake.output.truth_dtm)
write_vector(site.centrelines, snakemake.output.centrelines)
write_vector(site.polygons, snakemake.output.polygons)
log.info("peat valley: %d x %d cells, %d occluded, %.0f m2 of gully in %d gullies", site.observed.grid.width, site.observed.grid.height,
         int((site.observed.data != site.observed.data).sum()), site.polygons["area_m2"].sum(), len(site.polygons))
