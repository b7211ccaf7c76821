"""Rule gully_validate: Thommeret-style network lengths against the reference network, and the Fig. 9b map.

Paper protocol (METHODS.md 1.6): only reference gullies inside the catchment whose heads
fall within the DEM are scored; the unfiltered numbers are reported beside them.
"""

import pandas as pd

from kitegully import InputError
from kitegully.evaluate.network import NetworkScorer, footprint, scored_reference, validation_geometries
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
catchment = None
if getattr(snakemake.input, "catchment", None):
    cat = read_vector(snakemake.input.catchment, crs=crs)
    if len(cat) == 0 or not cat.geom_type.isin(["Polygon", "MultiPolygon"]).all():
        raise InputError(f"{snakemake.input.catchment}: the catchment must hold polygons")
    catchment = cat.geometry.union_all()
extracted = read_vector(snakemake.input.mapped_network, crs=crs)
gully, grid = read_raster(snakemake.input.gully_map)
# DEM footprint near the lines only: clips them exactly as the whole footprint would, far cheaper
domain = footprint(gully != 255, grid, near=[*reference.geometry, *extracted.geometry])
scored, not_scored, counts = scored_reference(reference, domain, float(cfg["reference_join_m"]), catchment)
log.info(
    "reference: %.0f m scored, %.0f m not scored (outside the catchment or fed only by heads off the DEM); "
    "%d of %d reference heads on the DEM",
    scored.length, not_scored.length, counts["heads_on_dem"], counts["heads"],
)
if scored.is_empty:
    log.warning("no reference line is scored: every reference head lies off the DEM or outside the catchment")
if catchment is not None:
    extracted = extracted.clip(catchment)
tol = float(cfg["tolerance_m"])
scorers = {
    "scored (paper protocol)": NetworkScorer([scored], domain, reference_all=reference),
    "all (unfiltered)": NetworkScorer(reference, domain),
}
clipped = scorers["all (unfiltered)"].clip(extracted)
table = scorers["scored (paper protocol)"].score(extracted, tol, clipped)
write_table(table, snakemake.output.table, floatfmt=".1f")
rows = []
for t in sorted({tol, *map(float, cfg["extra_tolerances_m"])}):
    ebuf = NetworkScorer.buffer(clipped, t)
    for name, scorer in scorers.items():
        v = scorer.score(extracted, t, clipped, ebuf)
        v.insert(0, "reference_lines", name)
        v.insert(0, "tolerance_m", t)
        rows.append(v)
write_table(pd.concat(rows, ignore_index=True), snakemake.output.tolerances, floatfmt=".1f")
for _, r in pd.concat(rows).pivot_table(index=["tolerance_m", "reference_lines"], columns="category", values="percent").iterrows():
    log.info("tolerance %.3g m, reference %s: good fit %.1f %%, false positive %.1f %%, false negative %.1f %%",
             r.name[0], r.name[1], r["good_fit"], r["false_positive"], r["false_negative"])
pct = dict(zip(table["category"], table["percent"]))
log.info(
    "network validation (tolerance %.3g m, paper protocol): reference %.0f m, good fit %.1f %%, "
    "false positive %.1f %%, false negative %.1f %%",
    tol, table["length_m"].iloc[0], pct["good_fit"], pct["false_positive"], pct["false_negative"],
)
dem, dgrid = read_raster(snakemake.input.dem)
pieces = validation_geometries([scored], extracted, tol, domain, reference_all=reference)
fig = validation_map(dem, gully == 1, grid, pieces, tol)
save_figure(fig, snakemake.output.figure, attribution=snakemake.params.attribution)
