"""Rule gully_validate: Thommeret-style network lengths against the reference network, and the Fig. 9b map.

Paper protocol (METHODS.md 1.6, :func:`kitegully.gully.validation.score_network`): only
reference gullies inside the catchment whose heads fall within the DEM are scored; the
unfiltered numbers are reported beside them.
"""

from concurrent.futures import ThreadPoolExecutor

from kitegully.gully.plots import validation_map
from kitegully.gully import ValidationParams, catchment_outline, check_reference, score_networks
from kitegully.io.figures import save_figure
from kitegully.io.raster import read_raster
from kitegully.io.tables import write_table
from kitegully.io.vectors import read_vector
from kitegully.logs import setup_script_logging

log = setup_script_logging(snakemake.log[0])
# no keep_freed_memory: its one malloc arena serialises the threads' GEOS allocations (110 vs 73-87 s, full size)
inp, out, crs = snakemake.input, snakemake.output, snakemake.params.crs
params = ValidationParams.from_config(snakemake.params.validation)
reference = check_reference(read_vector(inp.reference, crs=crs), inp.reference)
catchment = catchment_outline(read_vector(inp.catchment, crs=crs), inp.catchment) if getattr(inp, "catchment", None) else None
gully, grid = read_raster(inp.gully_map)
both = "table_digitised" in out.keys()  # gully.heads: both: the digitised heads alone too (the paper's procedure)
digitised = read_vector(inp.mapped_network_digitised, crs=crs) if both else None
with ThreadPoolExecutor(max_workers=1) as pool:  # the DEM decoded beside the scoring
    later = pool.submit(read_raster, inp.dem)
    res, alone = score_networks(reference, read_vector(inp.mapped_network, crs=crs), digitised, gully != 255, grid, params,
                                catchment)
dem, _ = later.result()
write_table(res.table, out.table, floatfmt=".1f")
write_table(res.tolerances, out.tolerances, floatfmt=".1f")
if both:
    write_table(alone.table, out.table_digitised, floatfmt=".1f")
    write_table(alone.tolerances, out.tolerances_digitised, floatfmt=".1f")
    log.info("digitised heads alone (the paper's procedure): good fit %.1f %% at %s m", alone.percent()["good_fit"],
             params.tolerance_m)
fig = validation_map(dem, gully == 1, grid, res.pieces, params.tolerance_m)
save_figure(fig, out.figure, attribution=snakemake.params.attribution)
