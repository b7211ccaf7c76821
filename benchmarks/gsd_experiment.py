"""Survey design: the default twin at its own GSD against the same twin photographed finer (evaluation only).

Reads the tables two runs of the same twin have written (``make run`` for ``results/kamech_twin``,
``make gsd-experiment`` for ``results/kamech_twin_gsd7cm``: same ground, heads, targets, flights and
checkpoints; only the photographs' pixel count, the DSM cell and the matching window differ) and puts
side by side what issues 16 and 17 score against the truth, and what each step cost:

- the DSMs at the checkpoints (both epochs) and against the true DSM by land cover;
- the polygons: IoU, precision and recall of the gullies wider than 2 m; median |error| of width and
  depth, and by section shape; total volume;
- the change: net volume against the truth and its stated SD, false detections at 95 %, headcut
  retreat (median |error| over the heads that retreated, and per head);
- the cost of each rule (Snakemake benchmark files: wall time and peak memory).

Nothing is computed from rasters here: every number is one the stages' own evaluation rules wrote.

    .venv/bin/python benchmarks/gsd_experiment.py [--base results/kamech_twin]
        [--fine results/kamech_twin_gsd7cm] [--out docs/benchmarks/gsd_experiment_session33]

Writes ``<out>.csv`` (quantity, base, fine) and ``<out>.md`` (the same, and the per-head table); with
``--figure PNG``, the profile along each retreated head's axis on the true DSMs and on both runs' DSMs
(epoch 2 co-registered: epoch 1 + the change stage's DoD), the true heads of both epochs marked.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import geopandas as gpd
import numpy as np
import pandas as pd

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "src"))

from kitegully.evaluate.dem import sample_bilinear  # noqa: E402
from kitegully.io.figures import new_figure, save_figure  # noqa: E402
from kitegully.io.raster import read_raster  # noqa: E402
from kitegully.io.tables import write_table  # noqa: E402

#: evaluation_summary rows reported, with the label they get here
CHANGE_ROWS = {
    "site_net_error_pct": "change: net volume error (%)",
    "site_net_sd_m3 (stated: correlated + co-registration)": "change: stated net SD (m3)",
    "false detection rate on unchanged cells, 95 %": "change: false detections at 95 % (%)",
    "detection rate of change > 2 sigma, 95 %": "change: true change > 2 sigma detected (%)",
    "headcut median |error| (heads that retreated)": "change: headcut |error| median, retreated heads (m)",
    "headcut |error| p90, heads that retreated, lip, stated": "change: headcut |error| p90, retreated heads (m)",
    "headcut |error| n, heads that retreated, lip, stated": "change: retreated heads measured (n)",
    "headcut |error| median, stable heads, lip, stated": "change: false retreat median, stable heads (m)",
    "headcut |error| median, heads that retreated, lip, method on the true surfaces":
        "change: headcut |error| median on the true DSMs (m)",
    "moritani MAE": "change: Moritani MAE (m)",
    "widening median |error|, all measured sections": "change: widening median |error| (m)",
}


def _read(path: Path) -> pd.DataFrame | None:
    return pd.read_csv(path) if path.exists() else None


def dsm_rows(run: Path) -> dict[str, float]:
    """Checkpoint SD and NMAD of both epochs; DSM − true DSM median and NMAD on gully and shrub cells."""
    out: dict[str, float] = {}
    for epoch, sub in (("epoch 1", ""), ("epoch 2", "epoch2/")):
        s = _read(run / f"validate/{sub}checkpoint_summary.csv")
        if s is not None:
            v = s.set_index("statistic")["value_m"]
            out[f"DSM {epoch}: checkpoint mean (m)"] = v["mean"]
            out[f"DSM {epoch}: checkpoint SD (m)"] = v["sd"]
            out[f"DSM {epoch}: checkpoint NMAD (m)"] = v["nmad"]
    lc = _read(run / "validate/dsm_error_by_landcover.csv")
    if lc is not None:
        lc = lc.set_index("landcover")
        for cls in ("ploughed", "gully", "shrub", "all"):
            if cls in lc.index:
                out[f"DSM epoch 1 - true DSM, {cls}: median (m)"] = lc.loc[cls, "median_m"]
                out[f"DSM epoch 1 - true DSM, {cls}: NMAD (m)"] = lc.loc[cls, "nmad_m"]
                out[f"DSM epoch 1, {cls}: valid cells (%)"] = lc.loc[cls, "valid_pct"]
    return out


def polygon_rows(run: Path) -> dict[str, float]:
    """IoU / precision / recall (gullies > 2 m wide), width, depth (all and by shape), volume."""
    out: dict[str, float] = {}
    sc = _read(run / "polygons/polygon_scores.csv")
    if sc is not None:
        wide = sc.loc[sc["kind"] == "wide"].iloc[0]
        for k in ("iou", "precision", "recall"):
            out[f"polygons: {k}, gullies > 2 m"] = wide[k]
    me = _read(run / "polygons/morphometry_errors.csv")
    if me is not None:
        me = me.set_index("quantity")
        out["polygons: width median |error| (m)"] = me.loc["width (m)", "median_abs_error"]
        out["polygons: depth median |error| (m)"] = me.loc["depth (m)", "median_abs_error"]
        out["polygons: depth median error (m)"] = me.loc["depth (m)", "median_error"]
        out["polygons: volume error (%)"] = me.loc["volume, all sections vs all true gullies (m3)", "error_pct"]
    sec = _read(run / "polygons/morphometry_errors_sections.csv")
    if sec is not None:
        for shape in ("U", "V"):
            e = sec.loc[sec["shape"] == shape, "depth_error_m"]
            out[f"polygons: depth median error, {shape} sections (m)"] = float(e.median()) if len(e) else np.nan
            out[f"polygons: depth median |error|, {shape} sections (m)"] = float(e.abs().median()) if len(e) else np.nan
            out[f"polygons: {shape} sections (n)"] = float(len(e))
    return out


def change_rows(run: Path) -> dict[str, float]:
    """The change evaluation's rows named in :data:`CHANGE_ROWS` (net, detections, headcuts, Moritani, widening)."""
    ev = _read(run / "change/evaluation_summary.csv")
    if ev is None:
        return {}
    v = ev.set_index("quantity")["value"]
    return {label: float(v[q]) for q, label in CHANGE_ROWS.items() if q in v.index}


def cost_rows(run: Path) -> dict[str, float]:
    """Wall time (s) and peak resident memory (MB) of each rule that ran, from Snakemake's benchmark files."""
    out: dict[str, float] = {}
    for tsv in sorted((run / "benchmarks").rglob("*.tsv")):
        rel = tsv.relative_to(run / "benchmarks").with_suffix("")
        if rel.parts[0] in ("obia", "closerange") and rel.name != "kite_scale":
            continue  # the close-range scenes do not depend on the kite photographs
        b = pd.read_csv(tsv, sep="\t")
        out[f"cost: {rel} wall (s)"] = float(b["s"].iloc[-1])
        out[f"cost: {rel} peak memory (MB)"] = float(b["max_rss"].iloc[-1])
    return out


def heads_table(base: Path, fine: Path) -> pd.DataFrame:
    """Per retreated head: the true retreat and each run's measured retreat and error."""
    cols = ["head_id", "true_gully_id", "true_retreat_m", "retreat_m", "error_m"]
    a = _read(base / "change/headcut_retreat_vs_truth.csv")
    b = _read(fine / "change/headcut_retreat_vs_truth.csv")
    if a is None or b is None:
        return pd.DataFrame()
    t = a[cols].merge(b[cols[:1] + cols[3:]], on="head_id", suffixes=("_base", "_fine"))
    return t.loc[t["true_retreat_m"] > 0].sort_values("true_retreat_m").reset_index(drop=True)


def plot_head_profiles(base: Path, fine: Path, path: Path, up_m: float = 5.0, down_m: float = 4.0,
                       step_m: float = 0.05) -> None:
    """Profiles along the epoch-1 axis of every retreated head measured in both runs (evaluation only).

    Distance 0 is the base run's epoch-1 lip on the base run's axis (the fine run measured on its own
    axis, usually within a few degrees), positive downstream; elevations relative to the true epoch-1
    DSM at the upslope end. Epoch 2 is drawn co-registered (epoch 1 + DoD), so its matching voids are
    gaps.

    Parameters
    ----------
    base, fine : Path
        The two runs' results folders (the twin's truth is read from ``base``).
    path : Path
        The PNG to write.
    up_m, down_m, step_m : float
        Profile extent upslope and downstream of the lip, and station spacing (m).
    """
    heads = heads_table(base, fine)
    heads = heads.loc[heads["retreat_m_base"].notna() & heads["retreat_m_fine"].notna()]
    rows = pd.read_csv(base / "change/headcut_retreat_vs_truth.csv").set_index("head_id")
    twin = base / "twin"
    truth = {e: read_raster(twin / sub / "truth/dsm.tif") for e, sub in (("1", ""), ("2", "epoch2"))}
    true_heads = {e: gpd.read_file(twin / sub / "truth/gully_heads.gpkg").set_index("gully_id")
                  for e, sub in (("1", ""), ("2", "epoch2"))}
    runs = {}
    for name, run in (("base", base), ("fine", fine)):
        z1, g = read_raster(run / "dense/dsm.tif")
        dod, gd = read_raster(run / "change/dod.tif")
        runs[name] = (z1, (z1 + dod) if gd.shape == g.shape else None, g)
    n = len(heads)
    ncol = min(4, max(n, 1))
    nrow = int(np.ceil(n / ncol)) if n else 1
    fig, axes = new_figure(nrow, ncol, figsize=(3.2 * ncol, 2.6 * nrow), squeeze=False, sharey=False)
    s = np.arange(-up_m, down_m + 1e-9, step_m)
    colours = {"truth": "black", "base": "tab:blue", "fine": "tab:orange"}
    labels = {"truth": "true DSM", "base": f"base ({base.name}) DSM", "fine": f"fine ({fine.name}) DSM"}
    for ax, h in zip(axes.ravel(), heads.itertuples()):
        r = rows.loc[h.head_id]
        t = np.array([r["axis_x"], r["axis_y"]])
        x, y = r["x1"] + s * t[0], r["y1"] + s * t[1]
        ref = sample_bilinear(truth["1"][0], truth["1"][1], x[:1], y[:1])[0]
        for key, surf in (("truth", (truth["1"][0], truth["2"][0], truth["1"][1])), ("base", runs["base"]), ("fine", runs["fine"])):
            z1, z2, g = surf
            ax.plot(s, sample_bilinear(z1, g, x, y) - ref, color=colours[key], lw=1.0, label=f"{labels[key]}, epoch 1")
            if z2 is not None:
                ax.plot(s, sample_bilinear(z2, g, x, y) - ref, color=colours[key], lw=1.0, ls="--", label=f"{labels[key]}, epoch 2")
        for e, ls in (("1", "-"), ("2", "--")):
            gid = int(h.true_gully_id)
            if gid in true_heads[e].index:
                p = true_heads[e].loc[gid].geometry
                ax.axvline((p.x - r["x1"]) * t[0] + (p.y - r["y1"]) * t[1], color="0.5", lw=0.8, ls=ls)
        ax.set_title(f"head {h.head_id}: true retreat {h.true_retreat_m:.2f} m\n"
                     f"measured {h.retreat_m_base:.1f} (base), {h.retreat_m_fine:.1f} m (fine)", fontsize=8)
        ax.set_xlabel("along the head axis, downstream (m)")
        ax.set_ylabel("elevation (m, relative)")
    for ax in axes.ravel()[n:]:
        ax.set_axis_off()
    if n:
        handles, lab = axes.ravel()[0].get_legend_handles_labels()
        fig.legend(handles, lab, loc="lower center", ncol=3, fontsize=7, bbox_to_anchor=(0.5, -0.06))
    fig.suptitle("Retreated heads: profiles along the base run's epoch-1 axis (grey lines: true heads, epoch 1 solid, "
                 "epoch 2 dashed)",
                 fontsize=9)
    fig.tight_layout()
    save_figure(fig, path, attribution="kitegully digital twin (synthetic); evaluation only")


def compare(base: Path, fine: Path) -> pd.DataFrame:
    """One row per quantity (DSM, polygons, change, cost) with the two runs' values.

    Parameters
    ----------
    base, fine : Path
        Results folders of the same twin at two survey designs.

    Returns
    -------
    DataFrame
        ``quantity, base, fine``; NaN where a run has no such table.
    """
    rows = []
    for fn in (dsm_rows, polygon_rows, change_rows, cost_rows):
        a, b = fn(base), fn(fine)
        for k in list(dict.fromkeys(list(a) + list(b))):
            rows.append({"quantity": k, "base": a.get(k, np.nan), "fine": b.get(k, np.nan)})
    return pd.DataFrame(rows)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", type=Path, default=REPO / "results/kamech_twin")
    ap.add_argument("--fine", type=Path, default=REPO / "results/kamech_twin_gsd7cm")
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks/out/gsd_experiment")
    ap.add_argument("--figure", type=Path, default=None, help="PNG of the retreated heads' profiles")
    a = ap.parse_args(argv)
    for run in (a.base, a.fine):
        if not (run / "change/evaluation_summary.csv").exists():
            print(f"{run}: no change/evaluation_summary.csv; run the chain for it first (make run, make gsd-experiment).")
            return 2
    table = compare(a.base, a.fine)
    heads = heads_table(a.base, a.fine)
    a.out.parent.mkdir(parents=True, exist_ok=True)
    write_table(table, a.out.with_suffix(".csv"), markdown=False)
    md = [f"# Survey design: {a.base.name} against {a.fine.name}", "",
          table.to_markdown(index=False, floatfmt=".3f"), "",
          "## Headcut retreat per head that retreated (m)", "",
          heads.to_markdown(index=False, floatfmt=".2f") if len(heads) else "(no matched heads)", ""]
    a.out.with_suffix(".md").write_text("\n".join(md))
    print(a.out.with_suffix(".md").read_text())
    if a.figure is not None:
        plot_head_profiles(a.base, a.fine, a.figure)
        print(f"wrote {a.figure}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
