"""Rule gully_validate: Thommeret-style network lengths against the reference network, and the Fig. 9b map."""

import numpy as np
import pandas as pd

from kitegully import InputError
from kitegully.evaluate.network import footprint, network_validation, validation_geometries
from kitegully.gully.plots import validation_map
from kitegully.io.figures import save_figure
from kitegully.io.raster import read_raster
from kitegully.io.tables import write_table
from kitegully.io.vectors import read_vector
from kitegully.logs import setup_script_logging

log = setup_script_logging(snakemake.log[0])
cfg = snakemake.params.cfg["validation"]
crs = snakemake.params.crs
reference = read_vector(snakemake.input.reference, crs=crs)
if not reference.geom_type.isin(["LineString", "MultiLineString"]).all() or len(reference) == 0:
    raise InputError(f"{snakemake.input.reference}: the reference network must hold lines")
extracted = read_vector(snakemake.input.mapped_network, crs=crs)
gully, grid = read_raster(snakemake.input.gully_map)
valid = gully != 255
domain = footprint(valid, grid)
tol = float(cfg["tolerance_m"])
table = network_validation(reference, extracted, tol, domain)
write_table(table, snakemake.output.table, floatfmt=".1f")
rows = []
for t in sorted({tol, *map(float, cfg["extra_tolerances_m"])}):
    v = network_validation(reference, extracted, t, domain)
    v.insert(0, "tolerance_m", t)
    rows.append(v)
write_table(pd.concat(rows, ignore_index=True), snakemake.output.tolerances, floatfmt=".1f")
pct = dict(zip(table["category"], table["percent"]))
log.info(
    "network validation (tolerance %.3g m): reference %.0f m, good fit %.1f %%, false positive %.1f %%, false negative %.1f %%",
    tol, table["length_m"].iloc[0], pct["good_fit"], pct["false_positive"], pct["false_negative"],
)
dem, dgrid = read_raster(snakemake.input.dem)
fig = validation_map(dem, gully == 1, grid, validation_geometries(reference, extracted, tol, domain), tol)
save_figure(fig, snakemake.output.figure, attribution=snakemake.params.attribution)
