"""Rule polygons_table1 (twin only, evaluation): paper Table 1 from the six automatic sets and nine simulated operators."""

from kitegully.io.raster import Raster
from kitegully.io.tables import write_table
from kitegully.io.vectors import read_vector, write_vector
from kitegully.logs import setup_script_logging
from kitegully.polygons.evaluation import observable_region_from_files, regenerate_table1
from kitegully.polygons.plots import comparison_map

log = setup_script_logging(snakemake.log[0])
inp, par, out = snakemake.input, snakemake.params, snakemake.output
dem = Raster.read(inp.dem)
auto = {t: read_vector(p) for t, p in zip(par.thresholds, inp.polygons)}
truth = read_vector(inp.truth, crs=dem.crs)
region = observable_region_from_files(dem.grid, inp.get("landcover"), inp.get("classes"))
stats, comp, ops = regenerate_table1(auto, truth, read_vector(inp.centrelines, crs=dem.crs), dem.grid, par.operators, par.seed,
                                     par.u_exponent, par.auto_threshold, region=region)
write_table(stats, out.table, floatfmt=".1f")
write_table(comp, out.comparison, floatfmt=".1f")
write_vector(ops, out.manual, layer="manual_polygons")
comparison_map(dem.data, dem.grid, auto[par.auto_threshold], ops, truth, out.figure, max_px=par.max_px, attribution=par.attribution)
log.info("Table 1:\n%s\n%s", stats.to_string(), comp.to_string())
