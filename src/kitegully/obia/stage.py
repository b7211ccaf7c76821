"""The obia stage's products, one function per rule (Mayr et al. 2016; METHODS.md, stage obia).

Close-range scenes: :func:`classify_scene_products` (rule ``obia_classify``),
:func:`evaluate_scene` and :func:`scene_figure` (rule ``obia_evaluate``),
:func:`summarise_scenes` and :func:`summary_figure` (rule ``obia_summary``). Kite scale:
:func:`kite_map_figure` (rule ``obia_kite_scale``, beside :func:`kitegully.obia.kite.bare_soil_map`)
and :func:`kite_accuracy` (rule ``obia_kite_accuracy``). The scripts only read inputs and
write what these return.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import geopandas as gpd
import numpy as np
import pandas as pd

from kitegully import InputError
from kitegully.io.figures import new_figure
from kitegully.io.raster import GridSpec
from kitegully.obia.accuracy import accuracies, accuracy_rows, area_error, confusion_matrix
from kitegully.obia.classify import NODATA, eroded_polygons
from kitegully.obia.scene import ObiaParams, SceneResult, classify_scene, marker_mask
from kitegully.obia.threshold import ThresholdResult

if TYPE_CHECKING:
    from matplotlib.figure import Figure

log = logging.getLogger(__name__)

#: ``obia:`` sub-sections read by :meth:`ObiaParams.from_config` (the method parameters).
METHOD_KEYS = ("features", "seeds", "growing", "exg_blur", "threshold", "classification")


# --------------------------------------------------------------------------- obia_classify
@dataclass
class ClassifiedScene:
    """Products of :func:`classify_scene_products`."""

    result: SceneResult
    polygons: gpd.GeoDataFrame
    histogram: pd.DataFrame
    info: dict[str, Any]


def classify_scene_products(
    rgb: np.ndarray,
    dem: np.ndarray,
    grid: GridSpec,
    dem_grid: GridSpec,
    markers: pd.DataFrame,
    obia_cfg: dict,
    scene: str,
    paths: dict[str, str],
) -> ClassifiedScene:
    """Classify one close-range scene into grass / eroded (ExG valley threshold, OBIA).

    Parameters
    ----------
    rgb, dem : the scene's orthophoto (3, H, W) and DEM (H, W).
    grid, dem_grid : their grids (must be equal).
    markers : DataFrame
        Surveyed GCP markers (``x, y, radius_m``): cells within ``marker_mask_factor`` radii are masked.
    obia_cfg : dict
        The ``obia:`` method sub-sections (:data:`METHOD_KEYS`).
    scene : str
        Scene name.
    paths : dict
        ``orthophoto``, ``dem``, ``markers`` paths, for messages.

    Returns
    -------
    ClassifiedScene
        The classification, eroded polygons, ExG histogram and the ``threshold.json`` facts.
    """
    if dem_grid != grid:
        raise InputError(f"{paths['dem']}: DEM grid {dem_grid} differs from the orthophoto grid {grid}")
    missing = {"x", "y", "radius_m"} - set(markers.columns)
    if missing:
        raise InputError(f"{paths['markers']}: missing columns {sorted(missing)}")
    params = ObiaParams.from_config(obia_cfg)
    masked = marker_mask(dem.shape, grid, markers, float(obia_cfg["classification"]["marker_mask_factor"]))
    res = classify_scene(rgb, dem, grid.cell, params, valid=~masked, source=str(paths["orthophoto"]))
    thr = res.threshold
    info = {
        "scene": scene,
        **thr.as_dict(),
        "n_seeds": int(res.seeds.max()),
        "n_segments": int(res.n_segments),
        "masked_cells": int(masked.sum()),
        "area_auto_m2": float(np.sum(res.classes == 1) * grid.cell ** 2),
        "area_auto_otsu_m2": float(np.sum(res.classes_otsu == 1) * grid.cell ** 2),
        "timings_s": res.timings_s,
    }
    if not thr.bimodal:
        log.warning("%s: ExG histogram is not bimodal (%s); every segment is %s", paths["orthophoto"], thr.reason,
                    params.unimodal_class)
    return ClassifiedScene(
        res,
        eroded_polygons(res.classes, grid.transform, grid.crs, scene),
        pd.DataFrame({"exg": thr.centres, "count": thr.counts}),
        info,
    )


# --------------------------------------------------------------------------- obia_evaluate
def evaluate_scene(
    classes: np.ndarray, classes_otsu: np.ndarray, truth: np.ndarray, cell: float, info: dict, scene: str
) -> dict[str, Any]:
    """Confusion matrices (valley and Otsu threshold) and areas of one scene against its truth mask.

    Returns the ``confusion.json`` record: ``scene, confusion, confusion_otsu, area_auto_m2,
    area_auto_otsu_m2, area_ref_m2, eroded_fraction_ref, threshold``. Cells with class 255
    (masked markers) are left out.

    Parameters
    ----------
    classes, classes_otsu : ndarray (H, W) uint8
        Maps by the valley and by Otsu's threshold (0 grass, 1 eroded, 255 masked).
    truth : ndarray (H, W) uint8
        Reference mask (0 grass, 1 eroded).
    cell : float
        Cell size (m).
    info : dict
        The scene's ``threshold.json`` facts; reads ``valley, otsu, bimodal, reason``.
    scene : str
        Scene name.

    Returns
    -------
    dict
        The ``confusion.json`` record; areas in m².
    """
    valid = classes != 255
    conf = confusion_matrix(classes, truth, valid=valid)
    conf_otsu = confusion_matrix(classes_otsu, truth, valid=valid)
    area_ref = float(np.sum((truth == 1) & valid) * cell ** 2)
    result = {
        "scene": scene,
        "confusion": conf.tolist(),
        "confusion_otsu": conf_otsu.tolist(),
        "area_auto_m2": float(np.sum(classes == 1) * cell ** 2),
        "area_auto_otsu_m2": float(np.sum(classes_otsu == 1) * cell ** 2),
        "area_ref_m2": area_ref,
        "eroded_fraction_ref": area_ref / float(valid.sum() * cell ** 2),
        "threshold": {k: info[k] for k in ("valley", "otsu", "bimodal", "reason")},
    }
    log.info("%s: OA %.1f %% (Otsu %.1f %%)", scene, 100 * accuracies(conf)["overall"],
             100 * accuracies(conf_otsu)["overall"])
    return result


def scene_figure(
    rgb: np.ndarray,
    segments: np.ndarray,
    classes: np.ndarray,
    truth: np.ndarray,
    histogram: pd.DataFrame,
    info: dict,
    grid: GridSpec,
    scene: str,
    overall_accuracy: float,
) -> Figure:
    """Scene figure (001 Figs 3-4): RGB, segments, ExG histogram with both thresholds, classification vs reference.

    Parameters
    ----------
    rgb : ndarray (3, H, W)
        Orthophoto, shown as uint8.
    segments : ndarray (H, W) int
        Segment labels.
    classes : ndarray (H, W) uint8
        Class codes (0 grass, 1 eroded, 255 masked).
    truth : ndarray (H, W) uint8
        Reference mask (0 grass, 1 eroded).
    histogram : DataFrame
        ExG histogram, columns ``exg`` and ``count``.
    info : dict
        The scene's ``threshold.json`` facts; reads ``n_segments, valley, otsu, bimodal, reason``.
    grid : GridSpec
        Scene grid; axes are in m from its corner.
    scene : str
        Scene name for the titles.
    overall_accuracy : float
        Overall accuracy as a fraction, shown in %.

    Returns
    -------
    Figure
        The 2 x 2 figure.
    """
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch
    from skimage.segmentation import find_boundaries

    valid = classes != 255
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
    hist = histogram
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
    ax.set_title("ExG histogram" + ("" if info["bimodal"] else f" - not bimodal: {info['reason']}"),
                 fontsize=8 if not info["bimodal"] else None)
    ax.legend(loc="upper left")
    ax = axes[1, 1]
    code = np.full(classes.shape, 4, dtype=np.uint8)
    code[valid & (classes == 1) & (truth == 1)] = 0
    code[valid & (classes == 0) & (truth == 0)] = 1
    code[valid & (classes == 1) & (truth == 0)] = 2
    code[valid & (classes == 0) & (truth == 1)] = 3
    colours = ["#a6611a", "#a6d96a", "#d7191c", "#2c7bb6", "#ffffff"]
    ax.imshow(code, extent=ext, cmap=ListedColormap(colours), vmin=-0.5, vmax=4.5, interpolation="nearest")
    labels = ["eroded, correct", "grass, correct", "mapped eroded, reference grass", "mapped grass, reference eroded",
              "masked (GCP marker)"]
    ax.legend(handles=[Patch(facecolor=c, edgecolor="0.3", label=l) for c, l in zip(colours, labels)], loc="lower left",
              fontsize=6)
    ax.set_title(f"classification vs reference: OA {100 * overall_accuracy:.1f} %")
    for a in axes.ravel()[[0, 1, 3]]:
        a.set_xlabel("x from scene corner (m)")
        a.set_ylabel("y from scene corner (m)")
        a.grid(False)
    fig.tight_layout()
    return fig


# --------------------------------------------------------------------------- obia_summary
@dataclass
class SceneSummary:
    """Products of :func:`summarise_scenes`: 001 Table 3 (accuracy), Table 2 (areas), valley vs Otsu."""

    accuracy: pd.DataFrame
    areas: pd.DataFrame
    comparison: pd.DataFrame


def summarise_scenes(results: Sequence[dict]) -> SceneSummary:
    """Accuracy per scene and over all scenes, eroded areas, and the valley vs Otsu comparison.

    ``results`` are the :func:`evaluate_scene` records. The comparison is sorted by the
    reference eroded share and ends with an ``all`` row (summed confusion matrices).
    """
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
        areas.append({"scene": r["scene"], "area_auto_m2": r["area_auto_m2"], "area_ref_m2": r["area_ref_m2"],
                      "error_pct": pct, "error_m2": m2})
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
    comp_df = pd.DataFrame(comp)
    comp_df = comp_df.sort_values("eroded_share_ref_pct").reset_index(drop=True)
    comp_df.loc[len(comp_df)] = {
        "scene": "all", "eroded_share_ref_pct": 100 * total[:, 1].sum() / total.sum(),
        "bimodal": bool(comp_df["bimodal"].all()),
        "valley_threshold": np.nan, "otsu_threshold": np.nan,
        "oa_valley_pct": 100 * accuracies(total)["overall"], "oa_otsu_pct": 100 * accuracies(total_otsu)["overall"],
        "area_error_valley_pct": np.nan, "area_error_otsu_pct": np.nan,
        "better": "valley" if accuracies(total)["overall"] > accuracies(total_otsu)["overall"] else "Otsu",
    }
    log.info("overall accuracy over %d scenes: %.2f %% (Otsu variant %.2f %%)", len(results),
             100 * accuracies(total)["overall"], 100 * accuracies(total_otsu)["overall"])
    return SceneSummary(pd.DataFrame(rows), pd.DataFrame(areas), comp_df)


def summary_figure(summary: SceneSummary, paper_overall_accuracy_pct: float = 94.3) -> Figure:
    """OA per scene (valley vs Otsu) against the eroded share, and automated vs reference eroded area."""
    c = summary.comparison[summary.comparison["scene"] != "all"]
    fig, axes = new_figure(1, 2, figsize=(9, 3.6))
    ax = axes[0]
    ax.plot(c["eroded_share_ref_pct"], c["oa_valley_pct"], "o", color="tab:red", label="valley threshold")
    ax.plot(c["eroded_share_ref_pct"], c["oa_otsu_pct"], "s", mfc="none", color="tab:blue", label="Otsu threshold")
    for _, r in c.iterrows():
        ax.annotate(r["scene"].replace("scene_", ""), (r["eroded_share_ref_pct"], r["oa_valley_pct"]), fontsize=6,
                    xytext=(3, 3), textcoords="offset points")
    ax.axhline(paper_overall_accuracy_pct, color="0.4", ls=":",
               label=f"Mayr et al. 2016, all scenes ({paper_overall_accuracy_pct} %)")
    ax.set_xlabel("reference eroded share of the scene (%)")
    ax.set_ylabel("overall accuracy (%)")
    ax.legend(fontsize=6)
    ax = axes[1]
    a = summary.areas
    lim = max(a["area_ref_m2"].max(), a["area_auto_m2"].max()) * 1.05 + 1
    ax.plot([0, lim], [0, lim], color="0.5", lw=0.8, label="1:1")
    ax.plot(a["area_ref_m2"], a["area_auto_m2"], "o", color="tab:brown", label="scenes")
    ax.set_xlabel("reference eroded area (m²)")
    ax.set_ylabel("automated eroded area (m²)")
    ax.legend(fontsize=6)
    fig.tight_layout()
    return fig


# --------------------------------------------------------------------------- obia_kite_scale
def kite_map_figure(ortho_path: str, classes: np.ndarray, grid: GridSpec, thr: ThresholdResult, figure_max_px: float,
                    index: str = "exg") -> Figure:
    """Orthophoto, the bare-soil map over it, and the blurred-index histogram with both thresholds.

    The orthophoto is read averaged down to at most ``figure_max_px`` pixels a side;
    ``index`` ("exg" or "ndvi", ``obia.classification.index``) names the thresholded index.

    Parameters
    ----------
    ortho_path : str
        RGB orthophoto (bands 1-3).
    classes : ndarray (H, W) uint8
        Bare-soil map on ``grid`` (1 bare).
    grid : GridSpec
        Grid of the map and the orthophoto.
    thr : ThresholdResult
        Global threshold with its histogram.
    figure_max_px : float
        Largest side of the shown orthophoto (px).
    index : str
        ``exg`` or ``ndvi``.

    Returns
    -------
    Figure
        The three-panel figure.
    """
    name = {"exg": "ExG", "ndvi": "NDVI"}[index]
    import rasterio
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch
    from rasterio.enums import Resampling

    step = max(1, int(np.ceil(max(grid.width, grid.height) / float(figure_max_px))))
    shape = (int(np.ceil(grid.height / step)), int(np.ceil(grid.width / step)))
    with rasterio.open(ortho_path) as src:
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
    unclassified = np.ma.masked_where(cls_small != NODATA, cls_small)
    axes[1].imshow(unclassified, extent=ext, cmap=ListedColormap(["#6baed6"]), alpha=0.9, interpolation="nearest")
    axes[1].legend(handles=[Patch(color="#d7301f", label=f"bare soil ({name} below the valley)"),
                            Patch(color="#6baed6", label="not classified (open water, no DSM)")],
                   loc="lower right", fontsize=7)
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
    for v in thr.valleys[:-1]:  # valleys above the lowest mode (straw / green shrubs), not used
        ax.axvline(v, color="0.3", ls=":", label=f"upper valley {v:.3f}")
    if thr.otsu is not None:
        ax.axvline(thr.otsu, color="#2b8cbe", ls="--", label=f"Otsu {thr.otsu:.3f}")
    ax.set_xlabel(f"{name}, Gaussian-blurred (-)")
    ax.set_ylabel("cells")
    ax.ticklabel_format(axis="y", style="sci", scilimits=(0, 0))
    ax.set_title(f"{name} histogram: " + ("bimodal" if thr.bimodal else f"not bimodal, {thr.reason}"),
                 fontsize=None if thr.bimodal else 8)
    ax.set_box_aspect(1.0)  # as tall as the maps beside it, not the whole row
    ax.legend(fontsize=7)
    return fig


# --------------------------------------------------------------------------- obia_kite_accuracy
@dataclass
class KiteAccuracy:
    """Products of :func:`kite_accuracy`."""

    accuracy: pd.DataFrame
    areas: pd.DataFrame
    per_class: pd.DataFrame


def kite_accuracy(
    bare: np.ndarray,
    grid: GridSpec,
    landcover_path: str,
    classes: pd.DataFrame,
    classes_path: str,
    bare_classes: Sequence[str],
    excluded_classes: Sequence[str],
    site: str,
) -> KiteAccuracy:
    """Accuracy of the kite-scale bare-soil map against the twin's land-cover truth.

    ExG separates vegetated from non-vegetated ground, so the reference "bare" class is the
    set of land-cover classes without plant cover (``bare_classes``); classes an analyst
    would mask before mapping (water, roofs: ``excluded_classes``) are left out of the
    confusion matrix. ``per_class`` gives, per land-cover class, its area, the share of its
    cells the map leaves unclassified (open water, no DSM or orthophoto data) and the share of the classified
    ones mapped as bare. The land cover is resampled (nearest) onto the map's grid.

    Parameters
    ----------
    bare : ndarray (H, W) uint8
        Bare-soil map (0 vegetated, 1 bare, 255 no data).
    grid : GridSpec
        Grid of the map.
    landcover_path : str
        Land-cover truth raster of class codes.
    classes : DataFrame
        Land-cover classes, columns ``code`` and ``name``.
    classes_path : str
        File of ``classes``, for messages.
    bare_classes : sequence of str
        Land-cover classes without plant cover (reference bare).
    excluded_classes : sequence of str
        Land-cover classes left out of the confusion matrix.
    site : str
        Site name for the ``scene`` column.

    Returns
    -------
    KiteAccuracy
        Accuracy rows (vegetated, bare) in %, mapped and reference bare areas (m²) and
        the per-class shares mapped bare.
    """
    import rasterio
    from rasterio.enums import Resampling
    from rasterio.warp import reproject

    if not {"code", "name"} <= set(classes.columns):
        raise InputError(f"{classes_path}: needs columns code, name")
    unknown = sorted((set(bare_classes) | set(excluded_classes)) - set(classes["name"]))
    if unknown:
        raise InputError(f"{classes_path}: land-cover classes {unknown} named in obia.kite_scale are not defined")
    bare_codes = classes.loc[classes["name"].isin(bare_classes), "code"].to_numpy()
    excluded_codes = classes.loc[classes["name"].isin(excluded_classes), "code"].to_numpy()
    with rasterio.open(landcover_path) as src:
        lc = np.full(bare.shape, 255, dtype=np.uint8)
        reproject(rasterio.band(src, 1), lc, dst_transform=grid.transform, dst_crs=grid.crs, dst_nodata=255,
                  resampling=Resampling.nearest)
    reference = np.where((lc == 255) | np.isin(lc, excluded_codes), 255, np.isin(lc, bare_codes).astype(np.uint8))
    conf = confusion_matrix(bare, reference)
    rows = accuracy_rows(site, conf)
    for r in rows:
        r["class"] = {"grass": "vegetated", "eroded": "bare"}[r["class"]]
    cell2 = grid.cell ** 2
    pct, m2 = area_error(conf[1].sum() * cell2, conf[:, 1].sum() * cell2)
    areas = pd.DataFrame([{"scene": site, "area_auto_m2": conf[1].sum() * cell2, "area_ref_m2": conf[:, 1].sum() * cell2,
                           "error_pct": pct, "error_m2": m2}])
    mapped = bare != 255
    per_class = []
    for code, name in zip(classes["code"], classes["name"]):
        here = lc == code
        if not here.any():
            continue
        cells = here & mapped
        per_class.append({
            "landcover_class": name,
            "reference": "excluded" if code in excluded_codes else ("bare" if code in bare_codes else "vegetated"),
            "area_m2": float(here.sum() * cell2),
            "not_classified_pct": 100.0 * float(np.mean(~mapped[here])),
            "mapped_bare_pct": 100.0 * float(np.mean(bare[cells] == 1)) if cells.any() else float("nan"),
        })
    acc = 100.0 * np.trace(conf) / max(conf.sum(), 1)
    log.info("kite-scale bare-soil map: OA %.1f %% over %d cells; per class: %s", acc, int(conf.sum()),
             ", ".join(f"{r['landcover_class']} {r['mapped_bare_pct']:.0f} % bare" for r in per_class))
    return KiteAccuracy(pd.DataFrame(rows), areas, pd.DataFrame(per_class))
