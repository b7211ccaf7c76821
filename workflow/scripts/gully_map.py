"""Rule gully_map: depth map, depth patches, network from the heads, final gully map and polygons."""

import numpy as np
import pandas as pd

from kitegully.evaluate.dem import read_checkpoints
from kitegully.gully.heads import HeadDetectionParams, dsm_noise_at_checkpoints
from kitegully.gully.inputs import check_dem, check_heads_on_dem, read_heads
from kitegully.gully.pipeline import GullyParams, map_gullies
from kitegully.io.raster import read_raster, write_raster
from kitegully.io.tables import write_table
from kitegully.io.vectors import write_vector
from kitegully.logs import setup_script_logging

log = setup_script_logging(snakemake.log[0])
cfg = snakemake.params.cfg
out = snakemake.output
dem, grid = read_raster(snakemake.input.dem)
check_dem(dem, snakemake.input.dem, grid.crs, snakemake.params.crs)
if snakemake.params.dem_source == "truth_plus_noise":
    log.warning("mapping on the truth-plus-noise stand-in DEM: NOT the photogrammetric DSM (gully.dem)")
digitised = cfg["heads"] != "automatic"
hx, hy = read_heads(snakemake.input.heads, snakemake.params.crs) if digitised else (np.zeros(0), np.zeros(0))
sz = None
if "checkpoints" in snakemake.input.keys():
    sz = dsm_noise_at_checkpoints(dem, grid, read_checkpoints(snakemake.input.checkpoints))
    log.info("DSM noise at the checkpoints (automatic heads): SD %.3f m", sz)
auto = HeadDetectionParams.from_config(cfg["automatic_heads"], sz) if cfg["heads"] != "digitised" else None
res = map_gullies(np.asarray(dem, dtype=np.float32), grid, hx, hy, GullyParams.from_config(cfg), workers=snakemake.threads,
                  auto_heads=auto)
if digitised:
    check_heads_on_dem(res.heads_inside, snakemake.input.heads)
if (~res.heads_inside).any():
    log.warning("%d of %d gully heads are off the DEM and were skipped", int((~res.heads_inside).sum()), hx.size)

write_raster(out.depth, res.depth, grid)
write_raster(out.smoothed, res.smoothed, grid)
nodata = ~np.isfinite(dem)
for path, mask in ((out.gully_map, res.gully), (out.gully_map_whole, res.gully_whole_patches)):
    m = mask.astype(np.uint8)
    m[nodata] = 255
    write_raster(path, m, grid, nodata=255)
write_vector(res.lines, out.network, layer="gully_network")
write_vector(res.extracted_lines, out.mapped_network, layer="gully_network_mapped")
write_vector(res.polygons, out.polygons, layer="gully_polygons")
res.network.save(out.network_cells)
write_table(res.patch_table, out.patches, markdown=False)

rows = [
    ("DEM source", snakemake.params.dem_source),
    ("DEM cells", grid.width * grid.height),
    ("cell size (m)", grid.cell),
    ("head source (gully.heads)", cfg["heads"]),
    ("gully heads", int(hx.size)),
    ("automatic heads", int(res.auto_heads.size)),
    ("heads on the DEM", int(res.heads_inside.sum())),
    ("head snapping", f"{cfg['head_snap']} cell within {cfg['head_snap_radius_m']} m"),
    ("tracing DEM smoothing sigma (m)", cfg["trace_smoothing_m"]),
    ("paths ending at an outlet", res.network.n_paths_to_outlet()),
    ("paths ending in a pit", res.network.n_paths_not_at_outlet()),
    ("traced network length (m)", round(float(res.lines["length_m"].sum()), 1)),
    ("mapped network length (m)", round(float(res.extracted_lines["length_m"].sum()), 1)),
    ("network segments", res.network.n_segments),
    ("max Strahler order", int(res.network.seg_order.max()) if res.network.n_segments else 0),
    ("depth patches kept", int(res.patch_table["kept"].sum())),
    ("gullies (polygons)", len(res.polygons)),
    ("gully area (m2)", round(float(res.polygons["area_m2"].sum()), 1)),
    ("gully volume (m3)", round(float(res.polygons["volume_m3"].sum()), 1)),
    ("gully area, whole-patch variant (m2)", round(float(res.gully_whole_patches.sum()) * grid.cell**2, 1)),
    ("interpolated hole cells", res.n_hole_cells),
    ("holes kept as open water from (m2)", cfg["water_min_area_m2"]),
    ("cells raised by filling", res.n_raised),
    ("flow routing across flats", cfg["flat_routing"]),
    ("flat cells routed by the flat mask", res.n_flat_routed),
] + [(f"time {k[:-2]} (s)", round(v, 2)) for k, v in res.timings_s.items()]
write_table(pd.DataFrame(rows, columns=["quantity", "value"]).astype({"value": str}), out.summary)
log.info("gully map done: %s", "; ".join(f"{k} = {v}" for k, v in rows))
