#!/usr/bin/env python
"""Kite-scale bare-soil map (obia stage) on every ensemble member's orthophoto, before and after.

For each member of the twin ensemble (``default`` = kamech_twin, ``ens1`` .. ``ens5``) whose
``dense/orthophoto.tif`` and ``dense/dsm.tif`` exist under ``<root>/<site>/`` (written by
``benchmarks/twin_ensemble.py``), the script runs the stage's library entry point
(:func:`kitegully.obia.kite.bare_soil_map`, the one the ``obia_kite_scale`` rule calls, with
:meth:`ObiaParams.from_config` of the member's merged ``obia`` section) into
``<out>/<site>/bare_soil.tif`` and scores it against the member's land-cover truth with
:func:`kitegully.obia.kite_accuracy` (as the ``obia_kite_accuracy`` rule does). The
"before" numbers are the member's stored ``obia/kite/accuracy.csv`` (the code that made the
ensemble run), read as they are; nothing under ``<root>`` is written.

Per member: overall accuracy, bare-soil producer's / user's accuracy, the threshold(s) and
the share of each land-cover class mapped as bare, then mean and worst rows.

With ``--diagnose MEMBER`` it also writes the diagnosis figure of that member
(``<out>/obia_ensemble_<member>_diagnosis.png``): the blurred-ExG histogram stacked by true
land-cover class with the old and new thresholds, and maps of where the old and the new map
disagree with the truth.

Usage::

    PYTHONPATH=src .venv/bin/python benchmarks/obia_ensemble.py --root /work/wt/ensrun/results \\
        [--members default,ens1,...] [--out results/benchmarks] [--diagnose ens2] [--reuse]

Writes ``<out>/obia_ensemble.csv`` and ``.md`` (about 1.5 min per member on the loaded
2-core machine). ``--reuse`` scores an existing ``<out>/<site>/bare_soil.tif`` again.

``--scenes RESULTS/<site>/obia/scenes`` (and ``--sfm-scenes RESULTS/<site>/closerange/scenes``,
the photogrammetric close-range orthophotos) also classifies the stored close-range scenes again
with the current code (:func:`kitegully.obia.classify_scene_products`, the obia_classify
rule's entry point) and compares their confusion matrices with the stored ``confusion.json``
(``<out>/obia_scenes_recheck.csv``/``.md``): the close-range (Mayr Table 3) accuracy must not
drop.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "src"))

from kitegully.config import load_yaml  # noqa: E402
from kitegully.io.raster import read_raster  # noqa: E402
from kitegully.io.tables import write_table  # noqa: E402
from kitegully.obia import kite_accuracy  # noqa: E402
from kitegully.obia.kite import bare_soil_map  # noqa: E402
from kitegully.obia.scene import ObiaParams  # noqa: E402

BASE = REPO / "config" / "sites" / "kamech_twin.yaml"
ENSEMBLE_DIR = REPO / "config" / "sites" / "ensemble"
MEMBERS = ["default", "ens1", "ens2", "ens3", "ens4", "ens5"]


def _merge(base: dict, over: dict) -> dict:
    out = dict(base)
    for k, v in over.items():
        out[k] = _merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


def member_config(member: str) -> dict:
    """The member's merged site configuration (base site file + its override file)."""
    cfg = load_yaml(BASE)
    if member != "default":
        cfg = _merge(cfg, load_yaml(ENSEMBLE_DIR / f"{member}.yaml"))
    return cfg


def _site(member: str, cfg: dict) -> str:
    return cfg["site"]["name"] if member != "default" else "kamech_twin"


def _score(bare_path: Path, site_dir: Path, cfg: dict, site: str):
    bare, grid = read_raster(str(bare_path))
    truth = site_dir / "twin" / "truth"
    ks = cfg["obia"]["kite_scale"]
    classes = pd.read_csv(truth / "landcover_classes.csv")
    return kite_accuracy(bare, grid, str(truth / "landcover.tif"), classes, str(truth / "landcover_classes.csv"),
                         ks["bare_landcover_classes"], ks["excluded_landcover_classes"], site)


def _row(acc, prefix: str) -> dict:
    a = acc.accuracy.set_index("class")
    out = {f"{prefix}oa_pct": float(a.loc["bare", "overall_accuracy"]),
           f"{prefix}bare_pa_pct": float(a.loc["bare", "producers_accuracy"]),
           f"{prefix}bare_ua_pct": float(a.loc["bare", "users_accuracy"])}
    return out


def _stored_before(site_dir: Path) -> dict:
    kite = site_dir / "obia" / "kite"
    out = {}
    if (kite / "accuracy.csv").exists():
        a = pd.read_csv(kite / "accuracy.csv").set_index("class")
        out = {"before_oa_pct": float(a.loc["bare", "overall_accuracy"]),
               "before_bare_pa_pct": float(a.loc["bare", "producers_accuracy"]),
               "before_bare_ua_pct": float(a.loc["bare", "users_accuracy"])}
    if (kite / "threshold.json").exists():
        out["before_threshold"] = json.loads((kite / "threshold.json").read_text())["valley"]
    if (kite / "landcover_agreement.csv").exists():
        pc = pd.read_csv(kite / "landcover_agreement.csv").set_index("landcover_class")["mapped_bare_pct"]
        out.update({f"before_{k}_bare_pct": float(v) for k, v in pc.items()})
    return out


def diagnosis_figure(site_dir: Path, new_bare: Path, params: ObiaParams, cfg: dict, member: str, out_png: Path, tile_cells: int) -> None:
    """Histogram by true class (old and new thresholds) and old / new error maps of one member."""
    import rasterio
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch
    from rasterio.enums import Resampling
    from rasterio.warp import reproject

    from kitegully.io.figures import new_figure, save_figure
    from kitegully.io.raster import grid_of, iter_tiles
    from kitegully.obia.kite import _read_tile
    from kitegully.obia.scene import blurred_exg

    truth = site_dir / "twin" / "truth"
    classes = pd.read_csv(truth / "landcover_classes.csv")
    names = dict(zip(classes["code"], classes["name"]))
    ks = cfg["obia"]["kite_scale"]
    bare_codes = set(classes.loc[classes["name"].isin(ks["bare_landcover_classes"]), "code"])
    excluded = set(classes.loc[classes["name"].isin(ks["excluded_landcover_classes"]), "code"])
    edges = np.linspace(-0.05, 0.35, 161)
    hist = {c: np.zeros(edges.size - 1, np.int64) for c in names}
    with rasterio.open(site_dir / "dense" / "orthophoto.tif") as o, rasterio.open(site_dir / "dense" / "dsm.tif") as d, \
            rasterio.open(truth / "landcover.tif") as lcs:
        grid = grid_of(o, "orthophoto")
        for read, core in iter_tiles(grid, tile_cells, params.blur_radius_cells + params.slope_window_cells):
            rgb, _, valid = _read_tile(o, d, read)
            _, blur = blurred_exg(*rgb, valid, params)
            r0, c0 = core.row_off - read.row_off, core.col_off - read.col_off
            inner = blur[r0:r0 + core.height, c0:c0 + core.width]
            lc = np.zeros(inner.shape, np.uint8)
            reproject(rasterio.band(lcs, 1), lc, dst_transform=o.window_transform(core), dst_crs=o.crs,
                      resampling=Resampling.nearest)
            for c in names:
                k = (lc == c) & np.isfinite(inner)
                hist[c] += np.histogram(inner[k], bins=edges)[0]
        step = 4
        shape = (grid.height // step, grid.width // step)
        lc_small = np.zeros(shape, np.uint8)
        t_small = o.transform * o.transform.scale(step, step)
        reproject(rasterio.band(lcs, 1), lc_small, dst_transform=t_small, dst_crs=o.crs, resampling=Resampling.nearest)
    ref = np.where(np.isin(lc_small, list(excluded)) | (lc_small == 0), 255, np.isin(lc_small, list(bare_codes)).astype(np.uint8))

    def _err(path):
        with rasterio.open(path) as s:
            m = s.read(1, out_shape=shape, resampling=Resampling.nearest)
        e = np.full(shape, 0, np.uint8)  # 0 no data / excluded
        ok = (m != 255) & (ref != 255)
        e[ok & (m == ref) & (ref == 1)] = 1
        e[ok & (m == ref) & (ref == 0)] = 2
        e[ok & (m == 1) & (ref == 0)] = 3
        e[ok & (m == 0) & (ref == 1)] = 4
        return e

    old = _err(site_dir / "obia" / "kite" / "bare_soil.tif")
    new = _err(new_bare)
    old_thr = json.loads((site_dir / "obia" / "kite" / "threshold.json").read_text())["valley"]
    new_info = json.loads((new_bare.parent / "threshold.json").read_text())
    fig, axes = new_figure(1, 3, figsize=(17, 5.0), gridspec_kw={"width_ratios": [1.1, 1, 1]}, layout="constrained")
    ax = axes[0]
    centres = 0.5 * (edges[:-1] + edges[1:])
    colours = {"bare_eroded": "#a6611a", "ploughed": "#dfc27d", "track": "#bababa", "gully": "#8c510a", "grass": "#c2e699",
               "shrub": "#31a354", "tree": "#006837", "water": "#2b8cbe", "building": "#e7298a"}
    bottom = np.zeros(centres.size)
    for c, name in names.items():
        ax.bar(centres, hist[c], bottom=bottom, width=edges[1] - edges[0], color=colours.get(name, "0.5"), label=name)
        bottom += hist[c]
    ax.axvline(old_thr, color="k", ls="--", label=f"old valley {old_thr:.3f}")
    ax.axvline(new_info["valley"], color="#d7301f", label=f"new valley {new_info['valley']:.3f}")
    ax.set_yscale("log")
    ax.set_ylim(1e3, None)
    ax.set_xlabel("ExG, Gaussian-blurred (-)")
    ax.set_ylabel("cells (log)")
    ax.set_title(f"{member}: blurred ExG by true land cover")
    ax.legend(fontsize=6, ncol=2)
    cmap = ListedColormap(["white", "#dfc27d", "#a1d99b", "#d7301f", "#2b8cbe"])
    x0, y0, x1, y1 = grid.bounds
    ext = (0.0, x1 - x0, 0.0, y1 - y0)
    for ax, e, title in ((axes[1], old, f"old map (valley {old_thr:.3f})"), (axes[2], new, f"new map (valley {new_info['valley']:.3f})")):
        ax.imshow(e, cmap=cmap, vmin=0, vmax=4, extent=ext, interpolation="nearest")
        ax.set_title(title)
        ax.set_xlabel(f"easting from {x0:.0f} m")
        ax.set_ylabel(f"northing from {y0:.0f} m")
    axes[2].legend(handles=[Patch(color="#dfc27d", label="bare, correct"), Patch(color="#a1d99b", label="vegetated, correct"),
                            Patch(color="#d7301f", label="vegetated mapped bare"), Patch(color="#2b8cbe", label="bare mapped vegetated")],
                   loc="lower right", fontsize=7)
    save_figure(fig, out_png)


def recheck_scenes(scenes_dir: Path, out: Path, reference_dir: Path | None = None, name: str = "obia_scenes_recheck") -> pd.DataFrame:
    """Classify every stored close-range scene again and compare with its stored confusion matrix.

    ``reference_dir`` (the obia stage's ``scenes`` folder) holds the markers and truth masks
    when ``scenes_dir`` is the closerange stage's (SfM orthophotos, same grid).
    """
    from kitegully.obia import classify_scene_products, evaluate_scene
    from kitegully.obia.accuracy import accuracies
    from kitegully.obia.stage import METHOD_KEYS

    cfg = load_yaml(BASE)["obia"]
    ocfg = {k: cfg[k] for k in METHOD_KEYS}
    rows, tot_old, tot_new = [], np.zeros((2, 2)), np.zeros((2, 2))
    for d in sorted(p for p in scenes_dir.glob("scene_*") if (p / "confusion.json").exists()):
        rgb, g = read_raster(str(d / "orthophoto.tif"), band=None)
        dem, dg = read_raster(str(d / "dem.tif"))
        ref = (reference_dir / d.name) if reference_dir is not None else d
        truth, _ = read_raster(str(ref / "truth" / "eroded.tif"))
        paths = {"orthophoto": str(d / "orthophoto.tif"), "dem": str(d / "dem.tif"), "markers": str(ref / "markers.csv")}
        sc = classify_scene_products(rgb, dem, g, dg, pd.read_csv(ref / "markers.csv"), ocfg, d.name, paths)
        new = np.asarray(evaluate_scene(sc.result.classes, sc.result.classes_otsu, truth, g.cell, sc.info, d.name)["confusion"])
        stored = json.loads((d / "confusion.json").read_text())
        old = np.asarray(stored["confusion"])
        tot_old += old
        tot_new += new
        rows.append({"scene": d.name, "valley_stored": stored["threshold"]["valley"], "valley_now": sc.info["valley"],
                     "oa_stored_pct": 100 * accuracies(old)["overall"], "oa_now_pct": 100 * accuracies(new)["overall"],
                     "eroded_pa_stored_pct": 100 * accuracies(old)["producers"][1], "eroded_pa_now_pct": 100 * accuracies(new)["producers"][1],
                     "eroded_ua_stored_pct": 100 * accuracies(old)["users"][1], "eroded_ua_now_pct": 100 * accuracies(new)["users"][1]})
    if rows:
        rows.append({"scene": "all", "oa_stored_pct": 100 * accuracies(tot_old)["overall"], "oa_now_pct": 100 * accuracies(tot_new)["overall"],
                     "eroded_pa_stored_pct": 100 * accuracies(tot_old)["producers"][1], "eroded_pa_now_pct": 100 * accuracies(tot_new)["producers"][1],
                     "eroded_ua_stored_pct": 100 * accuracies(tot_old)["users"][1], "eroded_ua_now_pct": 100 * accuracies(tot_new)["users"][1]})
    df = pd.DataFrame(rows)
    out.mkdir(parents=True, exist_ok=True)
    write_table(df, out / f"{name}.csv", floatfmt=".2f")
    print(df.to_string(index=False), flush=True)
    return df


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--root", default="results", help="folder holding <site>/dense and <site>/twin/truth of each member")
    ap.add_argument("--members", default=",".join(MEMBERS))
    ap.add_argument("--out", default="results/benchmarks")
    ap.add_argument("--diagnose", default=None, help="member for the diagnosis figure")
    ap.add_argument("--reuse", action="store_true", help="score an existing <out>/<site>/bare_soil.tif again")
    ap.add_argument("--scenes", default=None, help="stored close-range scenes folder (obia/scenes) to classify again and compare")
    ap.add_argument("--sfm-scenes", default=None, help="stored closerange/scenes folder (SfM orthophotos; needs --scenes for truth)")
    args = ap.parse_args()
    root, out = Path(args.root), Path(args.out)
    if args.scenes:
        recheck_scenes(Path(args.scenes), out)
    if args.sfm_scenes:
        recheck_scenes(Path(args.sfm_scenes), out, Path(args.scenes), "closerange_sfm_recheck")
    if args.members == "none":
        return 0
    rows = []
    for member in args.members.split(","):
        cfg = member_config(member)
        site = _site(member, cfg)
        site_dir = root / site
        ortho, dsm = site_dir / "dense" / "orthophoto.tif", site_dir / "dense" / "dsm.tif"
        if not (ortho.exists() and dsm.exists() and (site_dir / "twin" / "truth" / "landcover.tif").exists()):
            print(f"{member}: orthophoto, DSM or truth missing under {site_dir}: skipped", flush=True)
            continue
        params = ObiaParams.from_config(cfg["obia"])
        tile_cells = int(cfg["obia"]["kite_scale"]["tile_cells"])
        bare_path = out / "obia_ensemble" / site / "bare_soil.tif"
        t0 = time.perf_counter()
        if not (args.reuse and bare_path.exists()):
            thr = bare_soil_map(ortho, dsm, bare_path, params, tile_cells)
            (bare_path.parent / "threshold.json").write_text(json.dumps(thr.as_dict(), indent=2))
        info = json.loads((bare_path.parent / "threshold.json").read_text())
        dt = time.perf_counter() - t0
        acc = _score(bare_path, site_dir, cfg, site)
        row = {"member": member, "grass_greenness": cfg["twin"]["texture"]["grass_greenness"],
               "sun_elevation_deg": cfg["twin"]["texture"]["illumination"]["sun_elevation_deg"]}
        row.update(_stored_before(site_dir))
        row.update(_row(acc, "after_"))
        row["after_threshold"] = info["valley"]
        row["after_valleys"] = " ".join(f"{v:.3f}" for v in info.get("valleys", []))
        row.update({f"after_{r.landcover_class}_bare_pct": r.mapped_bare_pct for r in acc.per_class.itertuples()})
        row["map_s"] = dt
        rows.append(row)
        print(f"{member}: OA {row.get('before_oa_pct', float('nan')):.1f} -> {row['after_oa_pct']:.1f} %, "
              f"threshold {row.get('before_threshold')} -> {info['valley']} ({dt:.0f} s)", flush=True)
        if args.diagnose == member:
            diagnosis_figure(site_dir, bare_path, params, cfg, member, out / f"obia_ensemble_{member}_diagnosis.png", tile_cells)
    if not rows:
        print("no member found", flush=True)
        return 1
    df = pd.DataFrame(rows)
    num = df.select_dtypes("number")
    mean = {"member": "mean", **num.mean().to_dict()}
    worst = {"member": "worst"}
    for c in num.columns:
        if c.endswith(("oa_pct", "pa_pct", "ua_pct")):
            worst[c] = float(num[c].min())
    df = pd.concat([df, pd.DataFrame([mean, worst])], ignore_index=True)
    out.mkdir(parents=True, exist_ok=True)
    write_table(df, out / "obia_ensemble.csv", floatfmt=".1f")
    cols = ["member", "grass_greenness", "sun_elevation_deg", "before_oa_pct", "after_oa_pct", "before_bare_pa_pct",
            "after_bare_pa_pct", "before_bare_ua_pct", "after_bare_ua_pct", "before_threshold", "after_threshold"]
    print(df[[c for c in cols if c in df]].to_string(index=False), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
