"""Bare-soil map of the site's kite orthophoto (tiled OBIA), with polygons and a map figure."""

import json

import numpy as np
import rasterio
from matplotlib.colors import ListedColormap
from matplotlib.patches import Patch
from rasterio.enums import Resampling

from kitegully.io.figures import new_figure, save_figure
from kitegully.io.raster import read_raster
from kitegully.io.vectors import write_vector
from kitegully.logs import setup_script_logging
from kitegully.obia.classify import eroded_polygons
from kitegully.obia.kite import bare_soil_map
from kitegully.obia.scene import ObiaParams

log = setup_script_logging(snakemake.log[0])
cfg = snakemake.params.obia
params = ObiaParams.from_config(cfg)
thr = bare_soil_map(snakemake.input.orthophoto, snakemake.input.dsm, snakemake.output.bare_soil, params, int(cfg["kite_scale"]["tile_cells"]))
classes, grid = read_raster(snakemake.output.bare_soil)
polygons = eroded_polygons(classes, grid.transform, grid.crs)
write_vector(polygons, snakemake.output.polygons)
with open(snakemake.output.info, "w", encoding="utf-8") as fh:
    json.dump(thr.as_dict(), fh, indent=2)
bare = classes == 1
log.info("bare soil: %.1f m² in %d polygons (%.2f %% of the mapped cells)", float(bare.sum() * grid.cell ** 2),
         len(polygons), 100.0 * bare.sum() / max(int((classes != 255).sum()), 1))

# --- figure: orthophoto with the bare-soil map; blurred-ExG histogram with both thresholds
step = max(1, int(np.ceil(max(grid.width, grid.height) / float(cfg["kite_scale"]["figure_max_px"]))))
shape = (int(np.ceil(grid.height / step)), int(np.ceil(grid.width / step)))
with rasterio.open(snakemake.input.orthophoto) as src:
    rgb = src.read([1, 2, 3], out_shape=(3, *shape), resampling=Resampling.average).astype(np.float64)
lo, hi = np.nanpercentile(rgb, [1, 99])
img = np.clip((rgb - lo) / max(hi - lo, 1e-9), 0, 1).transpose(1, 2, 0)
cls_small = classes[::step, ::step][: shape[0], : shape[1]]
x0, y0, x1, y1 = grid.bounds
ext = (0.0, x1 - x0, 0.0, y1 - y0)
fig, axes = new_figure(1, 3, figsize=(15, 5.2), gridspec_kw={"width_ratios": [1, 1, 0.8]}, layout="constrained")
axes[0].imshow(img, extent=ext)
axes[0].set_title("orthophoto")
axes[1].imshow(img, extent=ext)
overlay = np.ma.masked_where(cls_small != 1, cls_small)
axes[1].imshow(overlay, extent=ext, cmap=ListedColormap(["#d7301f"]), alpha=0.75, interpolation="nearest")
axes[1].legend(handles=[Patch(color="#d7301f", label="bare soil (ExG below the valley)")], loc="lower right", fontsize=7)
axes[1].set_title("bare-soil map")
for ax in axes[:2]:
    ax.set_xlabel(f"easting from {x0:.0f} m")
    ax.set_ylabel(f"northing from {y0:.0f} m")
ax = axes[2]
ax.bar(thr.centres, thr.counts, width=thr.centres[1] - thr.centres[0], color="0.5")
nz = np.flatnonzero(thr.counts)
if nz.size:
    ax.set_xlim(thr.centres[nz[0]], thr.centres[nz[-1]])
if thr.valley is not None:
    ax.axvline(thr.valley, color="#d7301f", label=f"valley {thr.valley:.3f}")
if thr.otsu is not None:
    ax.axvline(thr.otsu, color="#2b8cbe", ls="--", label=f"Otsu {thr.otsu:.3f}")
ax.set_xlabel("ExG, Gaussian-blurred (-)")
ax.set_ylabel("cells")
ax.set_title("bimodal" if thr.bimodal else f"not bimodal: {thr.reason}", fontsize=8)
ax.legend(fontsize=7)
save_figure(fig, snakemake.output.figure, attribution=snakemake.params.attribution)
