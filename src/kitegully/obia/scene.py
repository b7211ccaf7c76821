"""The whole OBIA chain for one orthophoto + DEM (Mayr et al. 2016, sect. 2.3-2.4).

features (R, G, B, Wood slope; z-normalised) -> seeds (variance minima) -> seeded region
growing -> ExG, Gaussian blur -> histogram valley threshold (Otsu alongside) -> segment
mean ExG -> grass / eroded -> optional minimum-area filter.

The histogram leaves out cells whose blue band is the brightest (open water, sky-lit
shade: :func:`kitegully.obia.indices.blue_dominant`), and the valley is the one that
bounds the lowest ExG mode, bare soil (:func:`kitegully.obia.threshold.find_bare_threshold`):
on a scene of grass over soil that is the valley between the two peaks, as in the paper;
with senescent grass and green shrubs beside the soil it is the valley below the straw.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from kitegully import InputError
from kitegully.config import config_section
from kitegully.io.raster import GridSpec
from kitegully.obia.classify import ERODED, GRASS, NODATA, classify_segments, remove_small_eroded, segment_means
from kitegully.obia.features import normalise_features
from kitegully.obia.indices import (EXG_RANGE, NDVI_RANGE, blue_dominant, dn_step, excess_green, exg_step, gaussian_blur,
                                    local_range, ndvi, ndvi_step)
from kitegully.obia.seeds import generate_seeds
from kitegully.obia.slope import wood_slope
from kitegully.obia.srg import seeded_region_growing
from kitegully.obia.threshold import IndexHistogram, ThresholdResult, find_bare_threshold, fine_histogram

if TYPE_CHECKING:
    import pandas as pd

log = logging.getLogger("kitegully.obia")


#: Bare-soil indices the classification can threshold (``obia.classification.index``).
INDICES = ("exg", "ndvi")


@dataclass(frozen=True)
class ObiaParams:
    """Method parameters (config section ``obia``, see the stage schema).

    Attributes (beyond Mayr et al.'s, which the schema documents)
    ----------
    index : str
        ``obia.classification.index`` (optional, default ``exg``): the index whose segment
        means are thresholded. ``exg`` (Mayr et al.) needs R, G, B only; ``ndvi``
        (Bryson et al. 2013) needs a NIR band on the orthophoto's grid and is used where
        one exists [I]: bare soil and rock have NDVI ≈ 0–0.2, green plants ≫ 0, so the
        two classes lie far apart on NDVI whatever the plants' visible colour.
    water_ndvi_below : float or None
        ``obia.classification.water_ndvi_below`` (optional, default none): with
        ``index: ndvi``, cells whose blurred NDVI is below this value are open water: left
        out of the histogram, and segments whose mean blurred NDVI is below it are masked
        (no data) in the map [I] 0: water absorbs the
        NIR, so its NDVI is negative, while dry and wet soil or rock reflect more NIR than
        red (NDVI > 0). Without it a sea or pond forms a third histogram mode.
    """

    slope_window_cells: int = 5
    seed_bandwidth_cells: int = 15
    position_weight: float = 0.0
    growing_reference: str = "mean"
    blur_sigma_cells: float = 1.0
    blur_radius_cells: int = 2
    hist_bins: int = 256
    min_class_fraction: float = 0.01
    max_valley_ratio: float = 0.9
    unimodal_class: str = "grass"
    segment_feature: str = "blurred"
    min_area_m2: float = 0.0
    index: str = "exg"
    water_ndvi_below: float | None = None

    @classmethod
    def from_config(cls, obia: dict) -> "ObiaParams":
        """Parameters from the ``obia:`` method sub-sections (the others may be present).

        Raises
        ------
        InputError
            Naming a missing or unknown key (:func:`kitegully.config.config_section`).
        """
        config_section(obia, "obia", ("features", "seeds", "growing", "exg_blur", "threshold", "classification"),
                       optional=("scenes", "kite_scale"))
        for where, keys, optional in (
            ("features", ("slope_window_cells",), ()),
            ("seeds", ("bandwidth_cells",), ()),
            ("growing", ("position_weight", "reference"), ()),
            ("exg_blur", ("sigma_cells", "radius_cells"), ()),
            ("threshold", ("bins", "min_class_fraction", "max_valley_ratio", "unimodal_class"), ()),
            ("classification", ("segment_feature", "min_area_m2"), ("marker_mask_factor", "index", "water_ndvi_below")),
        ):
            config_section(obia[where], f"obia.{where}", keys, optional=optional)
        cl = obia["classification"]
        index = str(cl.get("index", "exg"))
        if index not in INDICES:
            raise InputError(f"obia.classification.index: must be one of {list(INDICES)}, got {index!r}")
        water = cl.get("water_ndvi_below")
        if water is not None and index != "ndvi":
            raise InputError("obia.classification.water_ndvi_below: needs index ndvi (the water mask is an NDVI value)")
        return cls(
            slope_window_cells=int(obia["features"]["slope_window_cells"]),
            seed_bandwidth_cells=int(obia["seeds"]["bandwidth_cells"]),
            position_weight=float(obia["growing"]["position_weight"]),
            growing_reference=str(obia["growing"]["reference"]),
            blur_sigma_cells=float(obia["exg_blur"]["sigma_cells"]),
            blur_radius_cells=int(obia["exg_blur"]["radius_cells"]),
            hist_bins=int(obia["threshold"]["bins"]),
            min_class_fraction=float(obia["threshold"]["min_class_fraction"]),
            max_valley_ratio=float(obia["threshold"]["max_valley_ratio"]),
            unimodal_class=str(obia["threshold"]["unimodal_class"]),
            segment_feature=str(obia["classification"]["segment_feature"]),
            min_area_m2=float(obia["classification"]["min_area_m2"]),
            index=index,
            water_ndvi_below=None if water is None else float(water),
        )

    @property
    def index_range(self) -> tuple[float, float]:
        """Fixed histogram range of the thresholded index."""
        return NDVI_RANGE if self.index == "ndvi" else EXG_RANGE


@dataclass
class SceneResult:
    """Everything the chain produced for one scene (rasters share the input grid)."""

    exg: np.ndarray
    exg_blur: np.ndarray
    slope_deg: np.ndarray
    seeds: np.ndarray
    segments: np.ndarray
    n_segments: int
    segment_exg: np.ndarray
    threshold: ThresholdResult
    classes: np.ndarray
    classes_otsu: np.ndarray
    timings_s: dict


def marker_mask(shape: tuple[int, int], grid: GridSpec, markers: pd.DataFrame | None, factor: float) -> np.ndarray:
    """Cells within ``factor`` x radius of any surveyed marker centre (``x, y, radius_m``).

    Parameters
    ----------
    shape : tuple of int
        Raster shape (rows, cols).
    grid : GridSpec
        Grid of the raster.
    markers : DataFrame or None
        Marker centres ``x, y`` and radii ``radius_m`` (m); None or empty gives an empty mask.
    factor : float
        Multiple of each marker's radius that is masked.

    Returns
    -------
    ndarray bool (H, W)
        True within the masked discs.
    """
    mask = np.zeros(shape, dtype=bool)
    if markers is None or len(markers) == 0:
        return mask
    xs, ys = grid.cell_centres()
    for _, m in markers.iterrows():
        r = float(m["radius_m"]) * factor
        cols = np.flatnonzero(np.abs(xs - m["x"]) <= r)
        rows = np.flatnonzero(np.abs(ys - m["y"]) <= r)
        if len(cols) == 0 or len(rows) == 0:
            continue
        sub = (xs[cols][None, :] - m["x"]) ** 2 + (ys[rows][:, None] - m["y"]) ** 2 <= r * r
        mask[np.ix_(rows, cols)] |= sub
    return mask


@dataclass
class Segmentation:
    """Products of :func:`segment`."""

    slope_deg: np.ndarray
    features: np.ndarray
    seeds: np.ndarray
    segments: np.ndarray
    n_segments: int
    timings_s: dict


def segment(
    red: np.ndarray,
    green: np.ndarray,
    blue: np.ndarray,
    dem: np.ndarray,
    cell: float,
    valid: np.ndarray,
    params: ObiaParams,
    t_start: float | None = None,
    nir: np.ndarray | None = None,
) -> Segmentation:
    """Segments of a scene or tile: Wood slope, normalised R, G, B, slope features, seeds, seeded region growing.

    The first phase of :func:`classify_scene` and of every tile of
    :func:`kitegully.obia.kite.bare_soil_map`. ``t_start`` (``time.perf_counter()``) lets
    the ``features`` timing include the caller's band preparation. A ``nir`` band, where
    the survey has one, joins the features (R, G, B, NIR, slope) [I]: plants and bare
    ground differ most in the NIR, so segment edges follow them there too.
    O(N log N) for N cells.

    Parameters
    ----------
    red, green, blue : ndarray (H, W)
        Colour bands, any scale.
    dem : ndarray (H, W)
        Surface heights (m).
    cell : float
        Cell size (m).
    valid : ndarray bool (H, W)
        Cells to segment.
    params : ObiaParams
        Method parameters (slope window, seed band width, growing).
    t_start : float or None
        Start time of the ``features`` timing (s, ``time.perf_counter()``); None starts it here.
    nir : ndarray (H, W) or None
        NIR band, where the survey has one.

    Returns
    -------
    Segmentation
        Slope (degrees), features, seeds, segment labels, segment count and timings (s).
    """
    t = {}
    t0 = time.perf_counter() if t_start is None else t_start
    slope = wood_slope(dem, cell, params.slope_window_cells)
    layers = [red, green, blue] + ([] if nir is None else [nir]) + [slope]
    feats = normalise_features(layers, valid)
    t["features"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    seeds = generate_seeds(feats, valid, params.seed_bandwidth_cells)
    t["seeds"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    segments, nseg = seeded_region_growing(feats, seeds, valid, params.position_weight, params.growing_reference)
    t["growing"] = time.perf_counter() - t0
    return Segmentation(slope, feats, seeds, segments, nseg, t)


def blurred_exg(red: np.ndarray, green: np.ndarray, blue: np.ndarray, valid: np.ndarray,
                params: ObiaParams) -> tuple[np.ndarray, np.ndarray]:
    """ExG (NaN off ``valid``) and its Gaussian blur (``exg_blur`` parameters). O(N).

    Parameters
    ----------
    red, green, blue : ndarray (H, W)
        Colour bands, any scale.
    valid : ndarray bool (H, W)
        Cells with data.
    params : ObiaParams
        Method parameters (blur sigma and radius).

    Returns
    -------
    exg : ndarray (H, W) float32
        ExG, NaN off ``valid``.
    exg_blur : ndarray (H, W) float32
        Its Gaussian blur, NaN off ``valid``.
    """
    exg = excess_green(red, green, blue)
    exg[~valid] = np.nan
    return exg, gaussian_blur(exg, params.blur_sigma_cells, params.blur_radius_cells)


def blurred_index(red: np.ndarray, green: np.ndarray, blue: np.ndarray, valid: np.ndarray, params: ObiaParams,
                  nir: np.ndarray | None = None, source: str = "orthophoto") -> tuple[np.ndarray, np.ndarray]:
    """The thresholded index (``params.index``: ExG, or NDVI from ``nir`` and red; NaN off
    ``valid``) and its Gaussian blur (``exg_blur`` parameters, used for either index). O(N).

    Parameters
    ----------
    red, green, blue : ndarray (H, W)
        Colour bands, any scale; NDVI uses red only.
    valid : ndarray bool (H, W)
        Cells with data.
    params : ObiaParams
        Method parameters (index, blur sigma and radius).
    nir : ndarray (H, W) or None
        NIR band; needed by ``index: ndvi``.
    source : str
        Name used in error messages.

    Returns
    -------
    index : ndarray (H, W) float32
        ExG or NDVI, NaN off ``valid``.
    blur : ndarray (H, W) float32
        Its Gaussian blur, NaN off ``valid``.

    Raises
    ------
    InputError
        ``index: ndvi`` without a NIR band.
    """
    if params.index == "exg":
        return blurred_exg(red, green, blue, valid, params)
    if nir is None:
        raise InputError(f"{source}: obia.classification.index is ndvi but no NIR band was given")
    v = ndvi(nir, red)
    v[~valid] = np.nan
    return v, gaussian_blur(v, params.blur_sigma_cells, params.blur_radius_cells)


def mixing_range(blur: np.ndarray, params: ObiaParams) -> np.ndarray:
    """Local range of the blurred index over the cells within one blur sigma of each cell
    (a (2 round(sigma) + 1)-cell square, at least 3 x 3; :func:`kitegully.obia.indices.local_range`).

    A cell next to a boundary between two covers has neighbours that far off on the other side
    (the mixed-cell test of :func:`kitegully.obia.threshold.find_bare_threshold`). O(N).
    """
    return local_range(blur, 2 * max(1, int(round(params.blur_sigma_cells))) + 1)


def index_step(red: np.ndarray, green: np.ndarray, blue: np.ndarray, params: ObiaParams, rgb_step: float,
               nir: np.ndarray | None = None, nir_step: float = 0.0) -> np.ndarray:
    """Each cell's one-DN step of the thresholded index (ExG or NDVI, ``params.index``). O(N).

    Parameters
    ----------
    red, green, blue : ndarray (H, W)
        Colour bands in DN.
    params : ObiaParams
        Method parameters (the index).
    rgb_step, nir_step : float
        One quantisation step of the colour bands and of the NIR band
        (:func:`kitegully.obia.indices.dn_step` of their data types).
    nir : ndarray (H, W) or None
        NIR band (``index: ndvi``).

    Returns
    -------
    ndarray (H, W) float32
        :func:`kitegully.obia.indices.exg_step` or :func:`kitegully.obia.indices.ndvi_step`.
    """
    if params.index == "exg":
        return exg_step(red, green, blue, rgb_step)
    return ndvi_step(nir, red, nir_step, rgb_step)


def classify_scene(rgb: np.ndarray, dem: np.ndarray, cell: float, params: ObiaParams, valid: np.ndarray | None = None, source: str = "scene") -> SceneResult:
    """Run the OBIA chain on one scene.

    Parameters
    ----------
    rgb
        (3, rows, cols) array, any scale (uint8 DN).
    dem
        float DEM on the same grid (m), NaN = no data.
    cell
        Cell size (m).
    params
        Method parameters.
    valid
        Optional mask of cells to use (e.g. without GCP markers); also excludes cells
        where the DEM is NaN or the colour is missing.
    source
        Name used in error messages (file or scene name).

    Complexity: O(N log N) for N cells (region growing); memory a few N-sized arrays.
    """
    if rgb.ndim != 3 or rgb.shape[0] < 3:
        raise InputError(f"{source}: orthophoto needs 3 bands (R, G, B), got shape {rgb.shape}")
    if rgb.shape[1:] != dem.shape:
        raise InputError(f"{source}: orthophoto {rgb.shape[1:]} and DEM {dem.shape} are not on the same grid")
    if params.index != "exg":
        raise InputError(f"{source}: the close-range scenes have no NIR band; obia.classification.index must be exg "
                         f"for them, got {params.index!r}")
    t = {}
    t0 = time.perf_counter()
    rgb_step = dn_step(rgb.dtype)
    red, green, blue = (rgb[i].astype(np.float32) for i in range(3))
    ok = np.isfinite(dem) & np.isfinite(red) & np.isfinite(green) & np.isfinite(blue)
    if valid is not None:
        ok &= valid
    if not ok.any():
        raise InputError(f"{source}: no valid cells (DEM all nodata or everything masked)")
    seg = segment(red, green, blue, dem, cell, ok, params, t0)
    slope, seeds, segments, nseg = seg.slope_deg, seg.seeds, seg.segments, seg.n_segments
    t.update(seg.timings_s)
    t0 = time.perf_counter()
    exg, exg_blur = blurred_exg(red, green, blue, ok, params)
    land = ~blue_dominant(red, green, blue)
    counted = (land if land.any() else np.ones(land.shape, dtype=bool)) & np.isfinite(exg_blur)
    values = exg_blur[counted]
    _, edges = fine_histogram(values, params.hist_bins)
    hist = IndexHistogram.of(values, exg_step(red, green, blue, rgb_step)[counted], mixing_range(exg_blur, params)[counted],
                             edges, quantised=rgb_step > 0)
    thr = find_bare_threshold(hist.counts, edges, params.hist_bins, params.min_class_fraction, params.max_valley_ratio,
                              fine_steps=hist.step_sums if hist.quantised else None, fine_by_range=hist.by_range)
    feature = exg_blur if params.segment_feature == "blurred" else exg
    means = segment_means(feature, segments, nseg)
    unimodal = GRASS if params.unimodal_class == "grass" else ERODED
    classes = remove_small_eroded(classify_segments(means, segments, thr.valley, unimodal), cell, params.min_area_m2)
    classes_otsu = remove_small_eroded(classify_segments(means, segments, thr.otsu, unimodal), cell, params.min_area_m2)
    classes[~ok] = NODATA
    classes_otsu[~ok] = NODATA
    t["classify"] = time.perf_counter() - t0
    log.info("%s: %d seeds, %d segments, valley %s, Otsu %s (%s)", source, int(seeds.max()), nseg,
             "none" if thr.valley is None else f"{thr.valley:.4f}",
             "none" if thr.otsu is None else f"{thr.otsu:.4f}", thr.reason)
    return SceneResult(exg, exg_blur, slope, seeds, segments, nseg, means, thr, classes, classes_otsu, t)


__all__ = ["INDICES", "ObiaParams", "SceneResult", "Segmentation", "blurred_exg", "blurred_index", "classify_scene", "marker_mask",
           "segment", "read_scene_rasters", "EXG_RANGE", "NDVI_RANGE"]


def read_scene_rasters(
    orthophoto_path: str, dem_path: str, *masks: str
) -> tuple[np.ndarray, np.ndarray, GridSpec, list[np.ndarray]]:
    """Read one scene's files: orthophoto (3 bands, uint8), DEM (float32) and optional masks (uint8) on one grid.

    The one reader of the scene files (the obia and closerange stages).

    Parameters
    ----------
    orthophoto_path, dem_path : the scene's orthophoto and DEM.
    masks : further single-band rasters of the scene (truth masks), read as uint8.

    Returns
    -------
    rgb (3, rows, cols) uint8, dem (rows, cols) float32 (NaN nodata), grid, list of masks.

    Raises
    ------
    InputError
        A file has fewer than 3 bands (orthophoto) or another grid than the orthophoto.
    """
    from kitegully.io.raster import read_raster

    rgb, grid = read_raster(orthophoto_path, band=None)
    if rgb.ndim != 3 or rgb.shape[0] < 3:
        raise InputError(f"{orthophoto_path}: the scene orthophoto needs 3 bands (R, G, B)")
    dem, dgrid = read_raster(dem_path)
    out = []
    for path, (arr, g) in [(dem_path, (dem, dgrid))] + [(m, read_raster(m)) for m in masks]:
        if arr.shape != (grid.height, grid.width) or not np.allclose((g.x0, g.y0, g.cell), (grid.x0, grid.y0, grid.cell)):
            raise InputError(f"{path}: its grid differs from the scene orthophoto {orthophoto_path}")
        out.append(arr)
    return rgb[:3].astype(np.uint8), dem.astype(np.float32), grid, [m.astype(np.uint8) for m in out[1:]]
