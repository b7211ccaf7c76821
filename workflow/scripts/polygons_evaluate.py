"""Rule polygons_evaluate (twin only, evaluation): polygon scores and morphometry errors against the true gullies."""

from kitegully.io.raster import Raster
from kitegully.io.tables import write_table
from kitegully.io.vectors import read_vector
from kitegully.logs import setup_script_logging
from kitegully.polygons.evaluation import evaluate_against_truth, observable_region_from_files

log = setup_script_logging(snakemake.log[0])
inp, out = snakemake.input, snakemake.output
dem = Raster.read(inp.dem)
region = observable_region_from_files(dem.grid, inp.get("landcover"), inp.get("classes"))
tabs = evaluate_against_truth(read_vector(inp.polygons), read_vector(inp.sections), read_vector(inp.truth, crs=dem.crs),
                              read_vector(inp.centrelines, crs=dem.crs), dem.grid, snakemake.params.cfg, snakemake.params.u_exponent,
                              region=region)
write_table(tabs["scores"], out.scores, floatfmt=".3f")
write_table(tabs["errors"], out.errors, floatfmt=".3f")
write_table(tabs["sections"], out.sections, markdown=False)
write_table(tabs["volumes"], out.volumes, floatfmt=".2f")
log.info("polygon scores (all, wide):\n%s\nmorphometry errors:\n%s", tabs["scores"].tail(2).to_string(), tabs["errors"].to_string())
