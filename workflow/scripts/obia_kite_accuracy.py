"""Accuracy of the kite-scale bare-soil map against the twin's land-cover truth (evaluation rule).

ExG separates vegetated from non-vegetated ground, so the reference "bare" class is the
set of land-cover classes without plant cover (``bare_landcover_classes``); classes an
analyst would mask before mapping (water, roofs: ``excluded_landcover_classes``) are left
out of the confusion matrix.  A second table gives, per land-cover class, the share of
its cells mapped as bare.
"""

import numpy as np
import pandas as pd
import rasterio
from rasterio.enums import Resampling
from rasterio.warp import reproject

from kitegully import InputError
from kitegully.io.raster import read_raster
from kitegully.io.tables import write_table
from kitegully.logs import setup_script_logging
from kitegully.obia.accuracy import accuracy_rows, area_error, confusion_matrix

log = setup_script_logging(snakemake.log[0])
inp, par = snakemake.input, snakemake.params
bare, grid = read_raster(inp.bare_soil)
classes = pd.read_csv(inp.landcover_classes)
if not {"code", "name"} <= set(classes.columns):
    raise InputError(f"{inp.landcover_classes}: needs columns code, name")
unknown = sorted((set(par.bare_classes) | set(par.excluded_classes)) - set(classes["name"]))
if unknown:
    raise InputError(f"{inp.landcover_classes}: land-cover classes {unknown} named in obia.kite_scale are not defined")
bare_codes = classes.loc[classes["name"].isin(par.bare_classes), "code"].to_numpy()
excluded_codes = classes.loc[classes["name"].isin(par.excluded_classes), "code"].to_numpy()
with rasterio.open(inp.landcover) as src:
    lc = np.full(bare.shape, 255, dtype=np.uint8)
    reproject(rasterio.band(src, 1), lc, dst_transform=grid.transform, dst_crs=grid.crs, dst_nodata=255, resampling=Resampling.nearest)
reference = np.where((lc == 255) | np.isin(lc, excluded_codes), 255, np.isin(lc, bare_codes).astype(np.uint8))
conf = confusion_matrix(bare, reference)
rows = accuracy_rows(par.site, conf)
for r in rows:
    r["class"] = {"grass": "vegetated", "eroded": "bare"}[r["class"]]
write_table(pd.DataFrame(rows), snakemake.output.accuracy, floatfmt=".1f")
cell2 = grid.cell ** 2
pct, m2 = area_error(conf[1].sum() * cell2, conf[:, 1].sum() * cell2)
write_table(pd.DataFrame([{"scene": par.site, "area_auto_m2": conf[1].sum() * cell2, "area_ref_m2": conf[:, 1].sum() * cell2,
                           "error_pct": pct, "error_m2": m2}]), snakemake.output.areas, floatfmt=".1f")
mapped = bare != 255
per_class = []
for code, name in zip(classes["code"], classes["name"]):
    cells = (lc == code) & mapped
    if not cells.any():
        continue
    per_class.append({
        "landcover_class": name,
        "reference": "excluded" if code in excluded_codes else ("bare" if code in bare_codes else "vegetated"),
        "area_m2": float(cells.sum() * cell2),
        "mapped_bare_pct": 100.0 * float(np.mean(bare[cells] == 1)),
    })
write_table(pd.DataFrame(per_class), snakemake.output.per_class, floatfmt=".1f")
acc = 100.0 * np.trace(conf) / max(conf.sum(), 1)
log.info("kite-scale bare-soil map: OA %.1f %% over %d cells; per class: %s", acc, int(conf.sum()),
         ", ".join(f"{r['landcover_class']} {r['mapped_bare_pct']:.0f} % bare" for r in per_class))
