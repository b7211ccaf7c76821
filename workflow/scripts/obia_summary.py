"""Accuracy tables over all close-range scenes (001 Tables 2-3) and valley vs Otsu."""

import json

import numpy as np
import pandas as pd

from kitegully.io.figures import new_figure, save_figure
from kitegully.io.tables import write_table
from kitegully.logs import setup_script_logging
from kitegully.obia.accuracy import accuracies, accuracy_rows, area_error

log = setup_script_logging(snakemake.log[0])
out = snakemake.output
results = [json.load(open(p, encoding="utf-8")) for p in snakemake.input.confusion]

rows, areas, comp = [], [], []
total = np.zeros((2, 2), dtype=np.int64)
total_otsu = np.zeros((2, 2), dtype=np.int64)
for r in results:
    conf = np.asarray(r["confusion"])
    conf_otsu = np.asarray(r["confusion_otsu"])
    total += conf
    total_otsu += conf_otsu
    rows += accuracy_rows(r["scene"], conf)
    pct, m2 = area_error(r["area_auto_m2"], r["area_ref_m2"])
    areas.append({"scene": r["scene"], "area_auto_m2": r["area_auto_m2"], "area_ref_m2": r["area_ref_m2"], "error_pct": pct, "error_m2": m2})
    oa, oa_otsu = accuracies(conf)["overall"], accuracies(conf_otsu)["overall"]
    thr = r["threshold"]
    comp.append({
        "scene": r["scene"],
        "eroded_share_ref_pct": 100 * r["eroded_fraction_ref"],
        "bimodal": thr["bimodal"],
        "valley_threshold": thr["valley"],
        "otsu_threshold": thr["otsu"],
        "oa_valley_pct": 100 * oa,
        "oa_otsu_pct": 100 * oa_otsu,
        "area_error_valley_pct": pct,
        "area_error_otsu_pct": area_error(r["area_auto_otsu_m2"], r["area_ref_m2"])[0],
        "better": "valley" if oa > oa_otsu else ("Otsu" if oa_otsu > oa else "equal"),
    })
rows += accuracy_rows("all", total)
accuracy = pd.DataFrame(rows)
write_table(accuracy, out.accuracy, floatfmt=".1f")
write_table(pd.DataFrame(areas), out.areas, floatfmt=".2f")
comp_df = pd.DataFrame(comp)
comp_df = comp_df.sort_values("eroded_share_ref_pct").reset_index(drop=True)
comp_df.loc[len(comp_df)] = {
    "scene": "all", "eroded_share_ref_pct": 100 * total[:, 1].sum() / total.sum(), "bimodal": bool(comp_df["bimodal"].all()),
    "valley_threshold": np.nan, "otsu_threshold": np.nan,
    "oa_valley_pct": 100 * accuracies(total)["overall"], "oa_otsu_pct": 100 * accuracies(total_otsu)["overall"],
    "area_error_valley_pct": np.nan, "area_error_otsu_pct": np.nan,
    "better": "valley" if accuracies(total)["overall"] > accuracies(total_otsu)["overall"] else "Otsu",
}
write_table(comp_df, out.comparison, floatfmt=".3g")
log.info("overall accuracy over %d scenes: %.2f %% (Otsu variant %.2f %%)", len(results),
         100 * accuracies(total)["overall"], 100 * accuracies(total_otsu)["overall"])

# --- summary figure: OA per scene, valley vs Otsu, against the eroded share
c = comp_df[comp_df["scene"] != "all"]
fig, axes = new_figure(1, 2, figsize=(9, 3.6))
ax = axes[0]
ax.plot(c["eroded_share_ref_pct"], c["oa_valley_pct"], "o", color="tab:red", label="valley threshold")
ax.plot(c["eroded_share_ref_pct"], c["oa_otsu_pct"], "s", mfc="none", color="tab:blue", label="Otsu threshold")
for _, r in c.iterrows():
    ax.annotate(r["scene"].replace("scene_", ""), (r["eroded_share_ref_pct"], r["oa_valley_pct"]), fontsize=6, xytext=(3, 3), textcoords="offset points")
ax.axhline(94.3, color="0.4", ls=":", label="Mayr et al. 2016, all scenes (94.3 %)")
ax.set_xlabel("reference eroded share of the scene (%)")
ax.set_ylabel("overall accuracy (%)")
ax.legend(fontsize=6)
ax = axes[1]
a = pd.DataFrame(areas)
lim = max(a["area_ref_m2"].max(), a["area_auto_m2"].max()) * 1.05 + 1
ax.plot([0, lim], [0, lim], color="0.5", lw=0.8, label="1:1")
ax.plot(a["area_ref_m2"], a["area_auto_m2"], "o", color="tab:brown", label="scenes")
ax.set_xlabel("reference eroded area (m²)")
ax.set_ylabel("automated eroded area (m²)")
ax.legend(fontsize=6)
fig.tight_layout()
save_figure(fig, out.figure, attribution="synthetic close-range scenes (kitegully twin)")
