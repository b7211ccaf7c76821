"""The low-cost survey against the twin's truth (rule ``lowcost_evaluate``; evaluation only).

NDVI per cover class, bare-ground indicators and the OBIA maps scored against the land cover
under the mosaic, and the targets and DSMs of both georeferencings against the true surface.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping

import numpy as np
import pandas as pd

from kitegully import InputError
from kitegully.config import config_section
from kitegully.evaluate.dem import nmad
from kitegully.io.raster import GridSpec, Raster, read_raster
from kitegully.io.tables import write_table
from kitegully.lowcost.georef import read_points
from kitegully.seeds import rng_for

if TYPE_CHECKING:
    from collections.abc import Collection


def _sim(d: Mapping[str, Any]):
    from kitegully.georef.similarity import Similarity
    return Similarity(float(d["scale"]), np.array(d["rotation"]), np.array(d["translation_m"]))


def _classes_under_mosaic(truth: Raster, grid: GridSpec, dsm: Raster, sim_est, sim_ref) -> np.ndarray:
    """Truth class of the ground each mosaic cell shows, as an operator picking patches in
    the mosaic sees it: the cell (with its DSM height) goes back to the model frame through
    the survey's georeferencing and out to the ground through the RTK-grade block
    (evaluation only), so a georeferencing error of the low-cost block does not mix classes."""
    xs, ys = np.meshgrid(*grid.cell_centres())
    r, c = dsm.grid.index(xs, ys)
    ok = (r >= 0) & (c >= 0) & (r < dsm.grid.height) & (c < dsm.grid.width)
    z = np.full(xs.shape, np.nan)
    z[ok] = dsm.data[r[ok], c[ok]]
    P = np.column_stack([xs.ravel(), ys.ravel(), z.ravel()])
    model = (P - sim_est.t) @ sim_est.R / sim_est.scale
    W = sim_ref.apply(model)
    tr, tc = truth.grid.index(W[:, 0], W[:, 1])
    fin = np.isfinite(W[:, 0]) & np.isfinite(W[:, 1])
    tr, tc = np.where(fin, tr, -1), np.where(fin, tc, -1)
    inside = (tr >= 0) & (tc >= 0) & (tr < truth.grid.height) & (tc < truth.grid.width)
    out = np.zeros(len(P), np.uint8)
    out[inside] = truth.data[tr[inside], tc[inside]]
    return out.reshape(xs.shape)


def _otsu(values: np.ndarray) -> float:
    from skimage.filters import threshold_otsu
    return float(threshold_otsu(values[np.isfinite(values)]))


def _accuracy(pred: np.ndarray, true: np.ndarray) -> dict:
    tp, tn = np.sum(pred & true), np.sum(~pred & ~true)
    fp, fn = np.sum(pred & ~true), np.sum(~pred & true)
    n = tp + tn + fp + fn
    po = (tp + tn) / n
    pe = ((tp + fp) * (tp + fn) + (tn + fn) * (tn + fp)) / n**2
    return {"overall_accuracy": po, "kappa": (po - pe) / (1 - pe), "bare_producers_accuracy": tp / max(tp + fn, 1),
            "bare_users_accuracy": tp / max(tp + fp, 1)}


def score_bare_soil_maps(survey_dir: str | Path, cls: np.ndarray, grid: GridSpec,
                         bare_classes: Collection[str]) -> pd.DataFrame:
    """Accuracy of the OBIA bare-soil maps (``bare_soil_ndvi.tif``, ``bare_soil_exg.tif``)
    against the land cover ``cls`` under the mosaic cells (truth class codes).

    Scored cells: land (not water, as an analyst masks the sea) mapped by both maps, so the
    two indices are compared on the same cells; reference "bare" = ``bare_classes``.
    Per map: overall accuracy, kappa, bare producer's and user's accuracy, the land cells
    the map left unmapped (NDVI: masked as water), and the share of each cover class
    mapped bare. O(cells).

    Parameters
    ----------
    survey_dir : path
        Folder holding ``bare_soil_ndvi.tif`` and ``bare_soil_exg.tif``.
    cls : ndarray (H, W) uint8
        Truth class code under each mosaic cell.
    grid : GridSpec
        Mosaic grid; both maps must lie on it.
    bare_classes : iterable of str
        Cover classes that count as bare.

    Returns
    -------
    DataFrame
        One row per map (ndvi, exg): accuracies, kappa, scored and unmapped land cells and
        the percentage of each class mapped bare.
    """
    from kitegully.lowcost.twin_site import CLASS_CODES
    sv = Path(survey_dir)
    maps = {}
    for name in ("ndvi", "exg"):
        data, g = read_raster(sv / f"bare_soil_{name}.tif")
        if data.shape != cls.shape or g.transform != grid.transform:
            raise InputError(f"{sv / f'bare_soil_{name}.tif'}: not on the mosaic grid {grid}")
        maps[name] = data
    unknown = sorted(set(bare_classes) - set(CLASS_CODES))
    if unknown:
        raise InputError(f"lowcost.evaluation.bare_classes: unknown cover classes {unknown} (known: {list(CLASS_CODES)})")
    land = (cls > 0) & (cls != CLASS_CODES["water"])
    both = land & (maps["ndvi"] != 255) & (maps["exg"] != 255)
    bare_true = np.isin(cls, [CLASS_CODES[c] for c in bare_classes])
    rows = []
    for name, m in maps.items():
        row = {"index": name, **_accuracy(m[both] == 1, bare_true[both]), "cells": int(both.sum()),
               "land_cells_unmapped": int(np.sum(land & (m == 255)))}
        for cname, code in CLASS_CODES.items():
            on = (cls == code) & (m != 255)
            row[f"{cname}_mapped_bare_pct"] = 100.0 * float(np.mean(m[on] == 1)) if on.any() else np.nan
        rows.append(row)
    return pd.DataFrame(rows)


def evaluate_lowcost(survey_dir: str | Path, truth_dir: str | Path, cfg: Mapping[str, Any], seed: int,
                     out_dir: str | Path) -> dict:
    """Score the survey's products against the twin's truth.

    Writes ``ndvi_by_class.csv`` (+ ``.png``: mean ± SD of 15 x 15 px patch means per class
    against the class NDVI the cameras see and the narrow-band NDVI), ``bare_ground_indicators.csv``
    (ExG and NDVI thresholded by Otsu, accuracy against the land cover; water left out by the
    observed NDVI < 0), ``bare_soil_obia.csv`` (the OBIA maps by NDVI and ExG),
    ``georef_truth.csv`` (target and DSM errors) and ``dsm_truth.csv`` (each DSM written:
    products, TIN, dense). O(mosaic cells).

    Parameters
    ----------
    survey_dir : path
        Output folder of :func:`survey_lowcost` with the bare-soil maps of :func:`map_bare_soil`.
    truth_dir : path
        The twin's truth: ``classes.tif``, ``classes.csv``, ``targets.csv``, ``dsm.tif``.
    cfg : mapping
        The ``lowcost.evaluation`` section: ``patch_px``, ``patches_per_class``, ``bare_classes``.
    seed : int
        The run's seed (patch stream ``rng_for(seed, "lowcost", "patches")``).
    out_dir : path
        Output folder, created if missing.

    Returns
    -------
    dict
        Largest absolute NDVI error, median and NMAD of the product DSM's error (m) and
        overall accuracy of each OBIA map; also written to ``evaluation.json``.
    """
    config_section(cfg, "lowcost.evaluation", ["patch_px", "patches_per_class", "bare_classes"])
    from kitegully.lowcost.twin_site import CLASS_CODES
    sv, tr, out = Path(survey_dir), Path(truth_dir), Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    nd = Raster.read(sv / "ndvi.tif")
    truth_cls = Raster.read(tr / "classes.tif")
    classes = pd.read_csv(tr / "classes.csv")
    gj = json.loads((sv / "georef.json").read_text())
    cls = _classes_under_mosaic(truth_cls, nd.grid, Raster.read(sv / "dsm.tif"), _sim(gj[gj["products"]]),
                                _sim(gj["similarity_rtk"]))
    k = int(cfg["patch_px"])
    rng = rng_for(seed, "lowcost", "patches")
    rows = []
    for name, code in CLASS_CODES.items():
        inside = (cls == code) & np.isfinite(nd.data)
        # windows fully inside the class: erode by the half patch
        from scipy import ndimage
        core = ndimage.binary_erosion(inside, np.ones((k, k), bool))
        rr, cc = np.nonzero(core)
        if len(rr) == 0:
            continue
        pick = rng.choice(len(rr), size=min(int(cfg["patches_per_class"]), len(rr)), replace=False)
        means = [float(np.mean(nd.data[r - k // 2:r + k // 2 + 1, c - k // 2:c + k // 2 + 1])) for r, c in zip(rr[pick], cc[pick])]
        t = classes.set_index("class").loc[name]
        rows.append({"class": name, "patches": len(means), "ndvi_mean": float(np.mean(means)), "ndvi_sd": float(np.std(means)),
                     "true_ndvi_camera": float(t["ndvi_camera"]), "true_ndvi_band": float(t["ndvi_band"]),
                     "error": float(np.mean(means) - t["ndvi_camera"])})
    tab = pd.DataFrame(rows)
    write_table(tab, out / "ndvi_by_class.csv")
    from kitegully.io.figures import new_figure, save_figure
    fig, ax = new_figure(figsize=(6, 4))
    x = np.arange(len(tab))
    ax.errorbar(x, tab["ndvi_mean"], yerr=tab["ndvi_sd"], fmt="o", capsize=4, label="mosaic patches (mean ± SD)")
    ax.plot(x, tab["true_ndvi_camera"], "kx", ms=9, label="truth as the cameras see it")
    ax.plot(x, tab["true_ndvi_band"], "r+", ms=9, label="truth, narrow bands (R 660, NIR 740 nm)")
    ax.axhline(0, color="0.6", lw=0.8)
    ax.set_xticks(x, tab["class"])
    ax.set_xlabel("cover class")
    ax.set_ylabel("NDVI (-)")
    ax.legend(fontsize=7)
    save_figure(fig, out / "ndvi_by_class.png")
    # bare-ground indicators
    exg = Raster.read(sv / "exg.tif").data
    land = np.isfinite(nd.data) & np.isfinite(exg) & (nd.data >= 0)          # observed water mask
    scored = land & (cls > 0) & (cls != CLASS_CODES["water"])
    bare_true = np.isin(cls, [CLASS_CODES[c] for c in cfg["bare_classes"]])
    ind = []
    for name, values in (("NDVI", nd.data), ("ExG", exg)):
        t = _otsu(values[land])
        pred = values < t
        ind.append({"indicator": name, "otsu_threshold": t, **_accuracy(pred[scored], bare_true[scored]),
                    "cells": int(scored.sum())})
    write_table(pd.DataFrame(ind), out / "bare_ground_indicators.csv")
    obia = score_bare_soil_maps(sv, cls, nd.grid, cfg["bare_classes"])
    write_table(obia, out / "bare_soil_obia.csv")
    # georeferencing against the truth
    tt = read_points(tr / "targets.csv", "true targets")
    grow = []
    for method, key in (("tape_horn_gps + tide shift (paper)", "targets_tape_horn_tide"),
                        ("tape_horn_gps + waterline levelled + tide", "targets_tape_horn_levelled"),
                        ("similarity_rtk", "targets_similarity_rtk")):
        d = np.array([np.array(gj[key][n]) - tt[n] for n in gj[key] if n in tt])
        grow.append({"method": method, "targets": len(d), "mean_3d_error_m": float(np.linalg.norm(d, axis=1).mean()),
                     "mean_horizontal_error_m": float(np.linalg.norm(d[:, :2], axis=1).mean()),
                     "mean_vertical_error_m": float(d[:, 2].mean())})
    tdsm = Raster.read(tr / "dsm.tif")
    sim_est, sim_ref = _sim(gj[gj["products"]]), _sim(gj["similarity_rtk"])
    drows = []
    for label, name in (("products (dsm.tif)", "dsm.tif"), ("TIN of the tie points", "dsm_tin.tif"),
                        ("dense matching, matched cells only", "dsm_dense.tif")):
        if name != "dsm.tif" and not (sv / name).exists():
            continue
        dsm = Raster.read(sv / name)
        xs, ys = np.meshgrid(*dsm.grid.cell_centres())
        r, c = tdsm.grid.index(xs, ys)
        inside = (r >= 0) & (c >= 0) & (r < tdsm.grid.height) & (c < tdsm.grid.width)
        ok = inside & np.isfinite(dsm.data)
        diff = dsm.data[ok] - tdsm.data[r[ok], c[ok]]
        m = float(np.median(diff))
        # the surface's shape alone: its points taken back to the model and out through the
        # RTK-grade block, so the low-cost block's georeferencing error does not enter
        P = np.column_stack([xs[ok], ys[ok], dsm.data[ok]])
        W = sim_ref.apply((P - sim_est.t) @ sim_est.R / sim_est.scale)
        rr, cc = tdsm.grid.index(W[:, 0], W[:, 1])
        k = (rr >= 0) & (cc >= 0) & (rr < tdsm.grid.height) & (cc < tdsm.grid.width)
        dr = W[k, 2] - tdsm.data[rr[k], cc[k]]
        mr = float(np.median(dr))
        drows.append({"dsm": label, "file": name, "cells": int(ok.sum()), "share_of_cells": float(ok.sum() / max(inside.sum(), 1)),
                      "median_error_m": m, "nmad_m": nmad(diff),
                      "rmse_m": float(np.sqrt(np.mean(diff**2))), "p95_abs_error_m": float(np.percentile(np.abs(diff), 95)),
                      "rtk_frame_median_error_m": mr, "rtk_frame_nmad_m": nmad(dr),
                      "rtk_frame_p95_abs_error_m": float(np.percentile(np.abs(dr - mr), 95))})
        if name == "dsm.tif":
            grow.append({"method": f"DSM ({gj['products']}) - true surface", "targets": int(ok.sum()),
                         "mean_3d_error_m": float(np.sqrt(np.mean(diff**2))), "mean_horizontal_error_m": np.nan,
                         "mean_vertical_error_m": m})
    write_table(pd.DataFrame(drows), out / "dsm_truth.csv")
    write_table(pd.DataFrame(grow), out / "georef_truth.csv")
    res = {"max_abs_ndvi_error": float(tab["error"].abs().max()),
           "dsm_median_error_m": drows[0]["median_error_m"], "dsm_nmad_m": drows[0]["nmad_m"],
           "bare_soil_obia_overall_accuracy": dict(zip(obia["index"], obia["overall_accuracy"].astype(float)))}
    (out / "evaluation.json").write_text(json.dumps(res, indent=1) + "\n")
    return res
