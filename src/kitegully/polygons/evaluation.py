"""Evaluation of the polygons: paper Table 1 (auto vs simulated manual sets) and scores
against the twin's true gullies (twin evaluation rules only; reads ``truth/``).

All area comparisons are made on the stage grid: every polygon set is rasterised (cell
centres inside) and areas are cell counts × cell area.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Mapping

import geopandas as gpd
import numpy as np
import pandas as pd
import scipy.ndimage as ndi
import shapely
from rasterio import features
from shapely.geometry import shape

from kitegully.config import config_section
from kitegully.io.raster import GridSpec

if TYPE_CHECKING:
    from collections.abc import Iterable, Sequence
    from pathlib import Path

    from kitegully.io.raster import Raster

#: The paper's Table 1 and sect. 5.3 numbers (Höfle et al. 2013; METHODS.md 3.4), m² or %.
PAPER_TABLE1 = {
    "sets": (6, 9),
    "min_area_m2": (6919, 5284),
    "max_area_m2": (8773, 9919),
    "mean_area_m2": (7777, 8411),
    "sd_area_m2": (665, 1097),
    "cv_pct": (8.6, 13.0),
    "min_over_max_pct": (78.9, 53.3),
    "intersection_m2": (6919, 5284),
    "union_m2": (8773, 10991),
    "intersection_over_mean_pct": (89.0, 62.8),
}
PAPER_COMPARISON = {
    "auto_in_union_pct (|A∩U|/|A|)": 99.8,
    "intersection_covered_pct (|A∩I|/|I|)": 99.5,
    "union_covered_pct (|A∩U|/|U|)": 79.7,
    "auto_over_intersection (|A|/|I|)": 1.7,
    "mean_auto_over_mean_manual_pct": 92.5,
}


@dataclass(frozen=True)
class EvaluationParams:
    """Scoring settings (``polygons.evaluation``, without ``operators``).

    Attributes
    ----------
    zone_m : float
        A mapped cell within this distance of a true gully counts towards that gully's
        precision and IoU (m) [I].
    wide_gully_m : float
        Gullies of mean true width above this are "wide" for the IoU target (m) [issue 16: 2 m].
    match_distance_m : float
        A cross-section is compared with the nearest true centreline reach within this
        distance (m) [I].
    """

    zone_m: float = 10.0
    wide_gully_m: float = 2.0
    match_distance_m: float = 2.0

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any]) -> "EvaluationParams":
        """Build from ``polygons.evaluation`` (``operators`` allowed, not read); raises InputError naming a bad key."""
        cfg = config_section(cfg, "polygons.evaluation", ["zone_m", "wide_gully_m", "match_distance_m"], optional=["operators"])
        return cls(zone_m=float(cfg["zone_m"]), wide_gully_m=float(cfg["wide_gully_m"]), match_distance_m=float(cfg["match_distance_m"]))


def rasterize(geoms: Iterable[shapely.Geometry | None], grid: GridSpec, values: Sequence[float] | None = None,
              dtype: type = np.uint8) -> np.ndarray:
    """Burn geometries (cell centres inside) on ``grid``; ``values`` default 1.

    Parameters
    ----------
    geoms : iterable of shapely geometry
        Geometries in the grid's CRS; None and empty ones are skipped.
    grid : GridSpec
        Grid to burn on.
    values : sequence or None
        Value burnt for each geometry; None = 1.
    dtype : dtype
        Type of the raster.

    Returns
    -------
    ndarray (H, W)
        The burnt raster, 0 outside the geometries.
    """
    geoms = [g for g in geoms if g is not None and not g.is_empty]
    shape = (grid.height, grid.width)
    if not geoms:
        return np.zeros(shape, dtype)
    vals = values if values is not None else [1] * len(geoms)
    return features.rasterize(list(zip(geoms, vals)), out_shape=shape, transform=grid.transform, fill=0, dtype=dtype)


def _stack_stats(masks: list[np.ndarray], cell_area: float) -> dict[str, float]:
    areas = np.array([m.sum() * cell_area for m in masks], float)
    inter = np.logical_and.reduce(masks).sum() * cell_area
    union = np.logical_or.reduce(masks).sum() * cell_area
    mean = areas.mean()
    sd = areas.std(ddof=1) if len(areas) > 1 else 0.0
    return {"sets": len(areas), "min_area_m2": areas.min(), "max_area_m2": areas.max(), "mean_area_m2": mean, "sd_area_m2": sd,
            "cv_pct": 100 * sd / mean if mean else np.nan, "min_over_max_pct": 100 * areas.min() / areas.max() if areas.max() else np.nan,
            "intersection_m2": inter, "union_m2": union, "intersection_over_mean_pct": 100 * inter / mean if mean else np.nan}


def table1(auto: Mapping[float, gpd.GeoDataFrame], manual: gpd.GeoDataFrame, grid: GridSpec, auto_threshold: float = 0.5) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Paper Table 1 regenerated, beside the paper's values.

    Parameters
    ----------
    auto : mapping threshold → GeoDataFrame
        The automatic polygon sets.
    manual : GeoDataFrame
        One (multi)polygon per simulated operator.
    grid : GridSpec
        Stage grid the areas are counted on.
    auto_threshold : float
        The set compared with the manual union and intersection (paper: 0.5 m).

    Returns
    -------
    stats : DataFrame
        ``statistic, auto, manual, paper_auto, paper_manual``.
    comparison : DataFrame
        ``statistic, value, paper`` for the t = ``auto_threshold`` polygon A against the
        manual union U and intersection I.
    """
    ca = grid.cell**2
    am = {t: rasterize(g.geometry, grid).astype(bool) for t, g in auto.items()}
    mm = [rasterize([g], grid).astype(bool) for g in manual.geometry]
    sa, sm = _stack_stats(list(am.values()), ca), _stack_stats(mm, ca)
    stats = pd.DataFrame([{"statistic": k, "auto": sa[k], "manual": sm[k], "paper_auto": PAPER_TABLE1[k][0], "paper_manual": PAPER_TABLE1[k][1]}
                          for k in PAPER_TABLE1])
    A = am[auto_threshold]
    U = np.logical_or.reduce(mm)
    I = np.logical_and.reduce(mm)
    a, u, i = A.sum(), U.sum(), I.sum()
    vals = [100 * (A & U).sum() / a if a else np.nan, 100 * (A & I).sum() / i if i else np.nan, 100 * (A & U).sum() / u if u else np.nan,
            a / i if i else np.nan, 100 * sa["mean_area_m2"] / sm["mean_area_m2"] if sm["mean_area_m2"] else np.nan]
    comp = pd.DataFrame({"statistic": list(PAPER_COMPARISON), "value": vals, "paper": list(PAPER_COMPARISON.values())})
    return stats, comp


def truth_table(centrelines: gpd.GeoDataFrame, truth_polys: gpd.GeoDataFrame, u_exponent: float) -> pd.DataFrame:
    """Per true gully: area, length, mean width (length-weighted), max depth and volume.

    The twin carves ``D (1 − |d/h|^p)`` across a half-width h (p = 1 for V, ``u_exponent``
    for U sections), so a reach's true section area is ``W D p / (p + 1)``.

    Parameters
    ----------
    centrelines : GeoDataFrame
        True centreline reaches: ``gully_id, shape, width_m, depth_m, depth_max_m, length_m``.
    truth_polys : GeoDataFrame
        True gully polygons: ``gully_id, kind, area_m2``.
    u_exponent : float
        Exponent p of the U sections.

    Returns
    -------
    DataFrame
        ``gully_id, kind, area_m2, length_m, max_depth_m, volume_true_m3, mean_width_m``; one row per polygon.
    """
    c = centrelines.copy()
    p = np.where(c["shape"] == "U", u_exponent, 1.0)
    c["area_true_m2"] = c["width_m"] * c["depth_m"] * p / (p + 1.0)
    c["vol"] = c["area_true_m2"] * c["length_m"]
    c["wl"] = c["width_m"] * c["length_m"]
    g = c.groupby("gully_id").agg(length_m=("length_m", "sum"), wl=("wl", "sum"), max_depth_m=("depth_max_m", "max"), volume_true_m3=("vol", "sum"))
    g["mean_width_m"] = g["wl"] / g["length_m"]
    g = g.drop(columns="wl")
    area = truth_polys.set_index("gully_id")[["kind", "area_m2"]]
    return area.join(g, how="left").reset_index()


def polygon_scores(auto: gpd.GeoDataFrame, truth_polys: gpd.GeoDataFrame, truth: pd.DataFrame, grid: GridSpec, params: EvaluationParams) -> pd.DataFrame:
    """Precision, recall and IoU per true gully and overall (cell counts on the stage grid).

    A mapped cell belongs to the nearest true gully within ``zone_m``; per gully g with
    true cells T_g and mapped cells A_g in its zone: precision = |A_g∩T_g|/|A_g|, recall =
    |A_g∩T_g|/|T_g|, IoU = |A_g∩T_g|/|A_g∪T_g|. Rows ``all`` (every mapped cell) and
    ``wide`` (gullies wider than ``wide_gully_m``, their zones) close the table.

    Parameters
    ----------
    auto : GeoDataFrame
        The mapped polygons.
    truth_polys : GeoDataFrame
        True gully polygons with ``gully_id``.
    truth : DataFrame
        :func:`truth_table` of the true gullies.
    grid : GridSpec
        Stage grid the cells are counted on.
    params : EvaluationParams
        Scoring settings; reads ``zone_m`` and ``wide_gully_m``.

    Returns
    -------
    DataFrame
        ``gully_id, kind, mean_width_m, true_area_m2, mapped_area_m2, overlap_m2, precision, recall, iou``;
        rows ``all`` and ``wide`` have ``gully_id`` -1.
    """
    ids = truth_polys["gully_id"].to_numpy()
    lab = rasterize(truth_polys.geometry, grid, values=(ids + 1).tolist(), dtype=np.int32)
    A = rasterize(auto.geometry, grid).astype(bool)
    dist, idx = ndi.distance_transform_edt(lab == 0, sampling=grid.cell, return_indices=True)
    zone = np.where(dist <= params.zone_m, lab[idx[0], idx[1]], 0)
    ca = grid.cell**2
    n = int(lab.max()) + 1
    T = np.bincount(lab.ravel(), minlength=n)
    Az = np.bincount(zone[A], minlength=n)
    TP = np.bincount(lab[A], minlength=n)
    info = truth.set_index("gully_id")
    rows = []
    for gid in ids:
        k = gid + 1
        t, a, tp = T[k], Az[k], TP[k]
        rows.append({"gully_id": int(gid), "kind": info.loc[gid, "kind"], "mean_width_m": info.loc[gid, "mean_width_m"],
                     "true_area_m2": t * ca, "mapped_area_m2": a * ca, "overlap_m2": tp * ca,
                     "precision": tp / a if a else np.nan, "recall": tp / t if t else np.nan, "iou": tp / (t + a - tp) if (t + a - tp) else np.nan})
    df = pd.DataFrame(rows)
    wide_ids = df.loc[df["mean_width_m"] > params.wide_gully_m, "gully_id"].to_numpy() + 1
    for name, sel_t, sel_a in (("all", lab > 0, A), ("wide", np.isin(lab, wide_ids), A & np.isin(zone, wide_ids))):
        t, a, tp = sel_t.sum(), sel_a.sum(), (sel_t & sel_a).sum()
        df.loc[len(df)] = {"gully_id": -1, "kind": name, "mean_width_m": np.nan, "true_area_m2": t * ca, "mapped_area_m2": a * ca,
                           "overlap_m2": tp * ca, "precision": tp / a if a else np.nan, "recall": tp / t if t else np.nan,
                           "iou": tp / (t + a - tp) if (t + a - tp) else np.nan}
    return df


def morphometry_errors(sections: gpd.GeoDataFrame, centrelines: gpd.GeoDataFrame, truth: pd.DataFrame, u_exponent: float,
                       params: EvaluationParams) -> tuple[pd.DataFrame, pd.DataFrame, pd.DataFrame]:
    """Cross-section width, depth and area against the nearest true reach; volume per gully.

    Returns (per-section errors, summary with median and P90 absolute errors and the
    volume totals, per-gully volumes).

    Parameters
    ----------
    sections : GeoDataFrame
        Measured cross-sections: ``polygon_id, station_m, width_m, depth_m, area_m2, slab_m``.
    centrelines : GeoDataFrame
        True centreline reaches: ``gully_id, shape, width_m, depth_m``.
    truth : DataFrame
        :func:`truth_table` of the true gullies.
    u_exponent : float
        Exponent p of the U sections.
    params : EvaluationParams
        Scoring settings; reads ``match_distance_m``.

    Returns
    -------
    errors : DataFrame
        One row per section matched to a true reach, with its errors (m, m²).
    summary : DataFrame
        Median, P90 and median signed errors of width, depth and area, and the volume totals (m³).
    volumes : DataFrame
        Measured and true volume (m³) and the volume error (%) per true gully.
    """
    c = centrelines.reset_index(drop=True)
    p = np.where(c["shape"] == "U", u_exponent, 1.0)
    c_area = (c["width_m"] * c["depth_m"] * p / (p + 1.0)).to_numpy()
    tree = shapely.STRtree(c.geometry.values)
    mids = [shapely.line_interpolate_point(g, 0.5, normalized=True) for g in sections.geometry]
    rows = []
    for i, (sec, mid) in enumerate(zip(sections.itertuples(), mids)):
        j = tree.query_nearest(mid, max_distance=params.match_distance_m)
        if len(j) == 0:
            continue
        j = int(j[0])
        rows.append({"polygon_id": sec.polygon_id, "station_m": sec.station_m, "gully_id": int(c.loc[j, "gully_id"]), "shape": c.loc[j, "shape"],
                     "width_m": sec.width_m, "width_true_m": c.loc[j, "width_m"], "depth_m": sec.depth_m, "depth_true_m": c.loc[j, "depth_m"],
                     "area_m2": sec.area_m2, "area_true_m2": c_area[j], "slab_m": sec.slab_m})
    per = pd.DataFrame(rows, columns=["polygon_id", "station_m", "gully_id", "shape", "width_m", "width_true_m", "depth_m", "depth_true_m",
                                      "area_m2", "area_true_m2", "slab_m"])
    for q in ("width", "depth", "area"):
        unit = "m2" if q == "area" else "m"
        per[f"{q}_error_{unit}"] = per[f"{q}_{unit}"] - per[f"{q}_true_{unit}"]
    summ = []
    for q, unit in (("width", "m"), ("depth", "m"), ("area", "m2")):
        e = per[f"{q}_error_{unit}"].abs()
        summ.append({"quantity": f"{q} ({unit})", "sections": len(e), "median_abs_error": e.median() if len(e) else np.nan,
                     "p90_abs_error": e.quantile(0.9) if len(e) else np.nan, "median_error": per[f"{q}_error_{unit}"].median() if len(e) else np.nan})
    vol = per.assign(v=per["area_m2"] * per["slab_m"]).groupby("gully_id")["v"].sum()
    gv = truth.set_index("gully_id")[["kind", "volume_true_m3"]].join(vol.rename("volume_m3"), how="left").fillna({"volume_m3": 0.0})
    gv["volume_error_pct"] = 100 * (gv["volume_m3"] - gv["volume_true_m3"]) / gv["volume_true_m3"]
    total_auto = float((sections["area_m2"] * sections["slab_m"]).sum()) if len(sections) else 0.0
    total_true = float(truth["volume_true_m3"].sum())
    measured = gv.loc[gv["volume_m3"] > 0]
    summ.append({"quantity": "volume, all sections vs all true gullies (m3)", "sections": len(sections), "median_abs_error": np.nan, "p90_abs_error": np.nan,
                 "median_error": np.nan, "measured": total_auto, "true": total_true, "error_pct": 100 * (total_auto - total_true) / total_true if total_true else np.nan})
    summ.append({"quantity": "volume, gullies with matched sections (m3)", "sections": len(per), "median_abs_error": np.nan, "p90_abs_error": np.nan,
                 "median_error": np.nan, "measured": float(measured["volume_m3"].sum()), "true": float(measured["volume_true_m3"].sum()),
                 "error_pct": 100 * (measured["volume_m3"].sum() - measured["volume_true_m3"].sum()) / measured["volume_true_m3"].sum() if len(measured) else np.nan})
    return per, pd.DataFrame(summ), gv.reset_index()


def observable_region(grid: GridSpec, landcover: Raster | None = None, classes: pd.DataFrame | None = None,
                      unseen_classes: tuple[str, ...] = ("water",)) -> shapely.Geometry:
    """The part of the stage grid where a survey sees the ground: the grid's extent less open water.

    A photogrammetric (or laser) survey of the twin sees the reservoir's flat surface, not the
    gully carved in its bed (the twin's true DSM is level there), so reaches under water are
    outside what any DEM of the site can measure; so is truth beyond the DEM's extent. The
    network reference drops its reaches under water in the same way (``twin.survey``).

    Parameters
    ----------
    grid : GridSpec
        The stage grid (its extent bounds the region).
    landcover : Raster, optional
        The twin's true land-cover raster (``truth/landcover.tif``); None = no classes unseen.
    classes : DataFrame, optional
        ``code, name`` of its classes (``truth/landcover_classes.csv``).
    unseen_classes : tuple of str
        Class names whose ground no survey sees.

    Returns
    -------
    shapely geometry
        The observable region (polygon or multipolygon).
    """
    region = shapely.box(*grid.bounds)
    if landcover is None or classes is None:
        return region
    codes = classes.loc[classes["name"].isin(unseen_classes), "code"].to_numpy()
    mask = np.isin(landcover.data, codes)
    if not mask.any():
        return region
    unseen = shapely.union_all([shape(g) for g, _v in
                                features.shapes(mask.astype(np.uint8), mask=mask, transform=landcover.grid.transform)])
    return shapely.difference(region, unseen)


def observable_region_from_files(grid: GridSpec, landcover_path: str | Path | None = None,
                                 classes_path: str | Path | None = None) -> shapely.Geometry:
    """:func:`observable_region` from a twin's ``truth/landcover.tif`` and ``truth/landcover_classes.csv``.

    Without the files (a DEM twin has no land cover) the region is the grid's extent.

    Parameters
    ----------
    grid : GridSpec
        The stage grid.
    landcover_path : str or Path or None
        The twin's true land-cover raster.
    classes_path : str or Path or None
        CSV with ``code, name`` of its classes.

    Returns
    -------
    shapely geometry
        The observable region.
    """
    if landcover_path is None or classes_path is None:
        return observable_region(grid)
    from kitegully.io.raster import Raster

    return observable_region(grid, Raster.read(landcover_path), pd.read_csv(classes_path))


def clip_truth(truth_polys: gpd.GeoDataFrame, centrelines: gpd.GeoDataFrame,
               region: shapely.Geometry | None) -> tuple[gpd.GeoDataFrame, gpd.GeoDataFrame]:
    """The true gullies and centreline reaches inside ``region`` (areas and lengths recomputed).

    Parameters
    ----------
    truth_polys, centrelines : GeoDataFrame
        The twin's true gully polygons (``area_m2``) and centreline reaches (``length_m``).
    region : shapely geometry or None
        :func:`observable_region`; None returns the inputs unchanged.

    Returns
    -------
    polygons, centrelines : GeoDataFrame
        Clipped copies without the parts (and rows) outside ``region``.
    """
    if region is None:
        return truth_polys, centrelines
    out = []
    for df, measure in ((truth_polys, "area_m2"), (centrelines, "length_m")):
        c = df.copy()
        c["geometry"] = shapely.intersection(c.geometry.values, region)
        c = c[~c.geometry.is_empty].copy()
        c[measure] = c.geometry.area if measure == "area_m2" else c.geometry.length
        out.append(c.reset_index(drop=True))
    return out[0], out[1]


def regenerate_table1(auto: Mapping[float, gpd.GeoDataFrame], truth_polys: gpd.GeoDataFrame, centrelines: gpd.GeoDataFrame,
                      grid: GridSpec, operators_cfg: Mapping[str, Any], seed: int, u_exponent: float,
                      auto_threshold: float = 0.5, region: shapely.Geometry | None = None) -> tuple[pd.DataFrame, pd.DataFrame, gpd.GeoDataFrame]:
    """Simulate the manual operators on the true outlines and build paper Table 1.

    ``region`` (:func:`observable_region`): the operators digitise only what the shaded DEM
    shows, so outlines under open water or beyond the DEM are not drawn.

    Returns (Table 1 statistics beside the paper, t = ``auto_threshold`` comparison with
    the manual union and intersection, the operators' outlines with their habits).

    Parameters
    ----------
    auto : mapping
        Automatic polygon set (GeoDataFrame) of each fill-depth threshold (m).
    truth_polys : GeoDataFrame
        True gully polygons (``gully_id, kind, area_m2``).
    centrelines : GeoDataFrame
        True centreline reaches.
    grid : GridSpec
        Stage grid the areas are counted on.
    operators_cfg : mapping
        Config of the simulated operators (:class:`kitegully.polygons.manual.OperatorParams`).
    seed : int
        Master seed.
    u_exponent : float
        Exponent p of the U sections.
    auto_threshold : float
        Threshold (m) of the set compared with the manual union and intersection.
    region : shapely geometry or None
        Observable region; None = the truth unclipped.

    Returns
    -------
    stats : DataFrame
        ``statistic, auto, manual, paper_auto, paper_manual``.
    comparison : DataFrame
        ``statistic, value, paper``.
    operators : GeoDataFrame
        One outline per operator, with its habits.
    """
    from kitegully.polygons.manual import OperatorParams, operator_outlines

    truth_polys, centrelines = clip_truth(truth_polys, centrelines, region)
    truth = truth_table(centrelines, truth_polys, u_exponent)
    ops = operator_outlines(truth_polys, dict(zip(truth["gully_id"], truth["max_depth_m"].fillna(0.0))),
                            OperatorParams.from_config(operators_cfg), seed)
    stats, comp = table1(auto, ops, grid, auto_threshold)
    return stats, comp, ops


def evaluate_against_truth(auto: gpd.GeoDataFrame, sections: gpd.GeoDataFrame, truth_polys: gpd.GeoDataFrame, centrelines: gpd.GeoDataFrame,
                           grid: GridSpec, cfg: Mapping[str, Any], u_exponent: float,
                           region: shapely.Geometry | None = None) -> dict[str, pd.DataFrame]:
    """Polygon scores and morphometry errors against the twin's true gullies.

    With ``region`` (:func:`observable_region`) the truth is what a survey can see: the
    gullies' parts under open water or beyond the DEM are left out of every score, and
    the volume they hold is reported beside the totals (rows "true volume not observable"
    and "volume, all sections vs all true gullies incl. not observable").

    Returns a dict of tables: ``scores`` (per gully, ``all``, ``wide``), ``errors``
    (median / P90 absolute errors, volume totals), ``sections`` (per cross-section) and
    ``volumes`` (per gully, with ``volume_not_observable_m3``).

    Parameters
    ----------
    auto : GeoDataFrame
        The mapped polygons.
    sections : GeoDataFrame
        Measured cross-sections (:func:`morphometry_errors`).
    truth_polys : GeoDataFrame
        True gully polygons.
    centrelines : GeoDataFrame
        True centreline reaches.
    grid : GridSpec
        Stage grid the cells are counted on.
    cfg : mapping
        The ``polygons.evaluation`` section (:class:`EvaluationParams`).
    u_exponent : float
        Exponent p of the U sections.
    region : shapely geometry or None
        Observable region; None = the whole truth.

    Returns
    -------
    dict of str to DataFrame
        ``scores``, ``errors``, ``sections`` and ``volumes``.
    """
    params = EvaluationParams.from_config(cfg)
    whole = truth_table(centrelines, truth_polys, u_exponent)
    truth_polys, centrelines = clip_truth(truth_polys, centrelines, region)
    truth = truth_table(centrelines, truth_polys, u_exponent)
    scores = polygon_scores(auto, truth_polys, truth, grid, params)
    per, summ, vol = morphometry_errors(sections, centrelines, truth, u_exponent, params)
    unseen = whole.set_index("gully_id")["volume_true_m3"].sub(truth.set_index("gully_id")["volume_true_m3"], fill_value=0.0)
    vol["volume_not_observable_m3"] = vol["gully_id"].map(unseen).fillna(0.0).to_numpy()
    total_whole = float(whole["volume_true_m3"].sum())
    measured = float(summ.loc[summ["quantity"] == "volume, all sections vs all true gullies (m3)", "measured"].iloc[0])
    summ.loc[len(summ)] = {"quantity": "true volume not observable (under open water, beyond the DEM) (m3)", "sections": 0,
                           "true": total_whole - float(truth["volume_true_m3"].sum())}
    summ.loc[len(summ)] = {"quantity": "volume, all sections vs all true gullies incl. not observable (m3)", "sections": len(sections),
                           "measured": measured, "true": total_whole,
                           "error_pct": 100 * (measured - total_whole) / total_whole if total_whole else np.nan}
    return {"scores": scores, "errors": summ, "sections": per, "volumes": vol}
