"""Rule gully_map: depth map, depth patches, network from the heads, final gully map and polygons."""

import numpy as np

from kitegully.gully import GullyParams, gully_summary, map_gullies, write_map_products
from kitegully.gully.heads import automatic_head_params
from kitegully.gully.inputs import (check_dem, check_heads_on_dem, read_heads, read_orthophoto_on_grid,
                                   read_tiled_inputs)
from kitegully.io.raster import read_raster, write_raster
from kitegully.io.tables import write_table
from kitegully.logs import setup_script_logging
from kitegully.memory import keep_freed_memory

log = setup_script_logging(snakemake.log[0])
keep_freed_memory()  # whole-DEM temporaries reuse freed heap memory (no page zeroing per array)
inp, out, crs, source = snakemake.input, snakemake.output, snakemake.params.crs, snakemake.params.dem_source
params, heads = GullyParams.from_config(snakemake.params.mapping), snakemake.params.heads
dem, grid = read_raster(inp.dem)
check_dem(dem, inp.dem, grid.crs, crs)
if source == "truth_plus_noise":
    log.warning("mapping on the truth-plus-noise stand-in DEM: NOT the photogrammetric DSM (gully.dem)")
hx, hy = read_heads(inp.heads, crs) if heads != "automatic" else (np.zeros(0), np.zeros(0))
auto = automatic_head_params(heads, snakemake.params.automatic_heads, dem, grid, inp.get("checkpoints"), params.head_snap,
                             needed=params.needs_incision_params)
tiled = read_tiled_inputs({k: inp[k] for k in ("smoothed", "depth", "filled", "trace_surface", "crowns")  # tiled sites
                           if k in inp.keys()})
ortho = read_orthophoto_on_grid(inp.ortho, grid) if "ortho" in inp.keys() and "crowns" not in inp.keys() else None
res = map_gullies(np.asarray(dem, dtype=np.float32), grid, hx, hy, params, workers=snakemake.threads,
                  auto_heads=auto if heads != "digitised" else None, incision=auto, ortho=ortho, **tiled,
                  on_depth=lambda s, d: (write_raster(out.depth, d, grid), write_raster(out.smoothed, s, grid)))  # beside the fill
if heads != "automatic": check_heads_on_dem(res.heads_inside, inp.heads)  # noqa: E701
write_map_products(res, np.isfinite(dem), grid, out)
summary = gully_summary(res, grid, params, source, hx.size, heads)
write_table(summary, out.summary)
log.info("gully map done: %s", "; ".join(f"{k} = {v}" for k, v in summary.itertuples(index=False)))
