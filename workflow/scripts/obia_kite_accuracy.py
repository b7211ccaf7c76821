"""Accuracy of the kite-scale bare-soil map against the twin's land-cover truth."""

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
inp = snakemake.input
bare, grid = read_raster(inp.bare_soil)
classes = pd.read_csv(inp.landcover_classes)
if not {"code", "name"} <= set(classes.columns):
    raise InputError(f"{inp.landcover_classes}: needs columns code, name")
bare_codes = classes.loc[classes["name"].isin(snakemake.params.bare_classes), "code"].to_numpy()
with rasterio.open(inp.landcover) as src:
    lc = np.full(bare.shape, 255, dtype=np.uint8)
    reproject(rasterio.band(src, 1), lc, dst_transform=grid.transform, dst_crs=grid.crs, dst_nodata=255, resampling=Resampling.nearest)
reference = np.where(lc == 255, 255, np.isin(lc, bare_codes).astype(np.uint8))
conf = confusion_matrix(bare, reference)
rows = accuracy_rows(snakemake.params.site, conf)
write_table(pd.DataFrame(rows), snakemake.output.accuracy, floatfmt=".1f")
cell2 = grid.cell ** 2
pct, m2 = area_error(conf[1].sum() * cell2, conf[:, 1].sum() * cell2)
write_table(pd.DataFrame([{"scene": snakemake.params.site, "area_auto_m2": conf[1].sum() * cell2, "area_ref_m2": conf[:, 1].sum() * cell2, "error_pct": pct, "error_m2": m2}]), snakemake.output.areas, floatfmt=".1f")
