"""Evaluate one scene against its truth mask: confusion matrices and the scene figure."""

import json

import numpy as np
import pandas as pd
from skimage.segmentation import find_boundaries

from matplotlib.colors import ListedColormap
from matplotlib.patches import Patch

from kitegully.io.figures import new_figure, save_figure
from kitegully.io.raster import read_raster
from kitegully.logs import setup_script_logging
from kitegully.obia.accuracy import accuracies, confusion_matrix

log = setup_script_logging(snakemake.log[0])
inp, out = snakemake.input, snakemake.output
scene = snakemake.wildcards.scene
rgb, grid = read_raster(inp.orthophoto, band=None)
segments, _ = read_raster(inp.segments)
classes, _ = read_raster(inp.classification)
classes_otsu, _ = read_raster(inp.classification_otsu)
truth, _ = read_raster(inp.truth_eroded)
info = json.load(open(inp.info, encoding="utf-8"))
valid = classes != 255
conf = confusion_matrix(classes, truth, valid=valid)
conf_otsu = confusion_matrix(classes_otsu, truth, valid=valid)
area_ref = float(np.sum((truth == 1) & valid) * grid.cell ** 2)
result = {
    "scene": scene,
    "confusion": conf.tolist(),
    "confusion_otsu": conf_otsu.tolist(),
    "area_auto_m2": float(np.sum(classes == 1) * grid.cell ** 2),
    "area_auto_otsu_m2": float(np.sum(classes_otsu == 1) * grid.cell ** 2),
    "area_ref_m2": area_ref,
    "eroded_fraction_ref": area_ref / float(valid.sum() * grid.cell ** 2),
    "threshold": {k: info[k] for k in ("valley", "otsu", "bimodal", "reason")},
}
with open(out.confusion, "w", encoding="utf-8") as fh:
    json.dump(result, fh, indent=2)
acc = accuracies(conf)
log.info("%s: OA %.1f %% (Otsu %.1f %%)", scene, 100 * acc["overall"], 100 * accuracies(conf_otsu)["overall"])

# --- figure: RGB, segments, histogram with both thresholds, classification vs reference
x0, y0, x1, y1 = grid.bounds
ext = (0.0, x1 - x0, 0.0, y1 - y0)
img = np.moveaxis(rgb[:3], 0, -1).astype(np.uint8)
fig, axes = new_figure(2, 2, figsize=(9, 8.6))
ax = axes[0, 0]
ax.imshow(img, extent=ext)
ax.set_title(f"{scene}: orthophoto (2 cm)")
ax = axes[0, 1]
seg_img = img.copy()
seg_img[find_boundaries(segments, mode="inner")] = (255, 255, 255)
ax.imshow(seg_img, extent=ext)
ax.set_title(f"seeded region growing: {info['n_segments']} segments")
ax = axes[1, 0]
hist = pd.read_csv(inp.histogram)
width = float(hist["exg"].diff().median())
ax.bar(hist["exg"], hist["count"], width=width, color="0.55", label="cells")
if info["valley"] is not None:
    ax.axvline(info["valley"], color="tab:red", lw=1.5, label=f"valley T = {info['valley']:.3f}")
if info["otsu"] is not None:
    ax.axvline(info["otsu"], color="tab:blue", ls="--", lw=1.5, label=f"Otsu T = {info['otsu']:.3f}")
shown = hist["exg"][hist["count"] > 0.001 * hist["count"].max()]
ax.set_xlim(shown.min() - 0.05, shown.max() + 0.05)
ax.set_xlabel("ExG, Gaussian-blurred (-)")
ax.set_ylabel("cells (count)")
ax.set_title("ExG histogram" + ("" if info["bimodal"] else f" - not bimodal: {info['reason']}"), fontsize=8 if not info["bimodal"] else None)
ax.legend(loc="upper left")
ax = axes[1, 1]
code = np.full(classes.shape, 4, dtype=np.uint8)
code[valid & (classes == 1) & (truth == 1)] = 0
code[valid & (classes == 0) & (truth == 0)] = 1
code[valid & (classes == 1) & (truth == 0)] = 2
code[valid & (classes == 0) & (truth == 1)] = 3
colours = ["#a6611a", "#a6d96a", "#d7191c", "#2c7bb6", "#ffffff"]
ax.imshow(code, extent=ext, cmap=ListedColormap(colours), vmin=-0.5, vmax=4.5, interpolation="nearest")
labels = ["eroded, correct", "grass, correct", "mapped eroded, reference grass", "mapped grass, reference eroded", "masked (GCP marker)"]
ax.legend(handles=[Patch(facecolor=c, edgecolor="0.3", label=l) for c, l in zip(colours, labels)], loc="lower left", fontsize=6)
ax.set_title(f"classification vs reference: OA {100 * acc['overall']:.1f} %")
for a in axes.ravel()[[0, 1, 3]]:
    a.set_xlabel("x from scene corner (m)")
    a.set_ylabel("y from scene corner (m)")
    a.grid(False)
fig.tight_layout()
save_figure(fig, out.figure, attribution="synthetic close-range scene (kitegully twin), method after Mayr et al. 2016")
