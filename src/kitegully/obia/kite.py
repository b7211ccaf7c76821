"""Kite-scale application: bare-soil map of a site-wide orthophoto + DSM, in tiles.

The histogram (and so the valley threshold) is global: the blurred index (ExG, or NDVI
where a NIR orthophoto exists and ``obia.classification.index`` is ``ndvi``) is
accumulated tile by tile into one fine fixed-range histogram (``FINE_BINS_PER_BIN`` x
``hist_bins`` bins over the index's range; cells whose blue band is the brightest, open
water above all, are left out: :func:`kitegully.obia.indices.blue_dominant`) and split at
the valley that bounds its lowest mode, bare soil
(:func:`kitegully.obia.threshold.find_bare_threshold`: the first valley on ``hist_bins``
bins over the fixed range, as before, then again on the finer re-binned part below it
while that part is bimodal, with bins no narrower than the index's one-DN step on those
cells and each side made of unmixed cells: the fine histogram also sums each cell's step
and counts cells by their local range, :class:`kitegully.obia.threshold.IndexHistogram`).
Segmentation and classification then run per tile (segments do not cross tile borders
[I]); the tile core is written to the output.
Segments most of whose cells are blue-dominant (open water) are left unclassified (255).
Memory: a few tile-sized arrays.  Cost: O(N log T) for N cells and tiles of T cells.
"""

from __future__ import annotations

import logging
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any, Iterator

import numpy as np
import rasterio
from rasterio.enums import Resampling
from rasterio.warp import reproject

from kitegully import InputError
from kitegully.io.raster import _profile, grid_of, iter_tiles
from kitegully.obia.classify import NODATA, classify_segments, remove_small_eroded, segment_means
from kitegully.obia.indices import blue_dominant, dn_step
from kitegully.obia.scene import ObiaParams, blurred_index, index_step, mixing_range, segment
from kitegully.obia.threshold import FINE_BINS_PER_BIN, IndexHistogram, ThresholdResult, find_bare_threshold

if TYPE_CHECKING:
    from rasterio.io import DatasetReader
    from rasterio.windows import Window

log = logging.getLogger("kitegully.obia.kite")


def _read_tile(ortho, dsm, window):
    rgb = ortho.read([1, 2, 3], window=window).astype(np.float32)
    valid = np.ones(rgb.shape[1:], dtype=bool)
    if ortho.count >= 4 and ortho.colorinterp[3] == rasterio.enums.ColorInterp.alpha:
        valid &= ortho.read(4, window=window) > 0
    if ortho.nodata is not None:
        valid &= ~np.all(rgb == ortho.nodata, axis=0)
    if rasterio.enums.MaskFlags.per_dataset in ortho.mask_flag_enums[0]:
        valid &= ortho.dataset_mask(window=window) > 0  # internal mask band (COG orthophoto)
    valid &= np.all(np.isfinite(rgb), axis=0)
    t = ortho.window_transform(window)
    dem = np.full(rgb.shape[1:], np.nan, dtype=np.float32)
    reproject(
        rasterio.band(dsm, 1), dem, dst_transform=t, dst_crs=ortho.crs,
        dst_nodata=np.nan, resampling=Resampling.bilinear,
    )
    valid &= np.isfinite(dem)
    return rgb, dem, valid


def _read_nir(nir, window, valid) -> np.ndarray | None:
    """The NIR band of ``window`` (band 1), or None without a NIR orthophoto; clears
    ``valid`` where it is missing (NaN or its nodata)."""
    if nir is None:
        return None
    band = nir.read(1, window=window).astype(np.float32)
    if nir.nodata is not None and np.isfinite(nir.nodata):
        valid &= band != nir.nodata
    valid &= np.isfinite(band)
    return band


def _tile_index(rgb, nir_band, valid, params, source):
    """Blurred index of a tile for the histogram; with a water threshold, cells of open
    water leave ``valid`` first (returns the raw index, its blur and the water mask)."""
    raw, blur = blurred_index(*rgb, valid, params, nir_band, source)
    wet = np.zeros(valid.shape, dtype=bool)
    if params.water_ndvi_below is not None:
        wet = valid & (blur < params.water_ndvi_below)
        if wet.any():
            valid &= ~wet
            raw, blur = blurred_index(*rgb, valid, params, nir_band, source)
    return raw, blur, wet


def _check_grids(ortho, dsm, ortho_path, dsm_path) -> None:
    """Raise InputError unless the DSM can be resampled onto the orthophoto grid.

    Both need the same CRS and north-up square cells, and the DSM must cover the
    orthophoto (up to one DSM cell at the edges [I]); cell size and alignment may differ
    (the DSM is resampled bilinearly onto the orthophoto cells).
    """
    for path, src in ((ortho_path, ortho), (dsm_path, dsm)):
        grid_of(src, path)
    if ortho.crs != dsm.crs:
        raise InputError(f"{dsm_path}: CRS {dsm.crs} does not match the orthophoto's {ortho.crs} ({ortho_path})")
    ob, db = ortho.bounds, dsm.bounds
    tol = abs(dsm.transform.a)
    if db.left > ob.left + tol or db.right < ob.right - tol or db.bottom > ob.bottom + tol or db.top < ob.top - tol:
        raise InputError(
            f"{dsm_path}: DSM extent {tuple(round(v, 2) for v in db)} does not cover the orthophoto "
            f"{ortho_path} extent {tuple(round(v, 2) for v in ob)}"
        )


def _check_nir(ortho, nir, ortho_path, nir_path) -> None:
    """Raise InputError unless the NIR orthophoto lies on the RGB orthophoto's grid."""
    if nir.crs != ortho.crs or nir.transform != ortho.transform or nir.shape != ortho.shape:
        raise InputError(f"{nir_path}: NIR orthophoto grid ({nir.crs}, {nir.shape}, {tuple(nir.transform)[:6]}) is not the "
                         f"RGB orthophoto's ({ortho.crs}, {ortho.shape}, {tuple(ortho.transform)[:6]}, {ortho_path})")


@contextmanager
def open_kite_inputs(ortho_path: str | Path, dsm_path: str | Path, nir_path: str | Path | None, params: ObiaParams,
                     tile_cells: int) -> Iterator[tuple[Any, Any, Any, Any, int]]:
    """Open and check the kite map's inputs: yields ``(ortho, dsm, nir or None, grid, halo)``.

    ``halo`` is the cells each block reads beyond its core (index blur plus slope window).

    Parameters
    ----------
    ortho_path : path
        RGB orthophoto (bands 1-3).
    dsm_path : path
        DSM in the orthophoto's CRS, covering the orthophoto.
    nir_path : path or None
        NIR orthophoto (band 1) on the RGB orthophoto's grid.
    params : ObiaParams
        Method parameters; ``index: ndvi`` needs ``nir_path``.
    tile_cells : int
        Tile side (cells); at least 4 seed band widths, else ValueError.

    Yields
    ------
    ortho, dsm : DatasetReader
        The open orthophoto and DSM.
    nir : DatasetReader or None
        The open NIR orthophoto.
    grid : GridSpec
        The orthophoto's grid.
    halo : int
        Cells each block reads beyond its core.

    Raises
    ------
    InputError
        Unreadable files, grids that do not fit, ``index: ndvi`` without ``nir_path``.
    """
    if params.index == "ndvi" and nir_path is None:
        raise InputError(f"{ortho_path}: obia.classification.index is ndvi but the survey has no NIR orthophoto")
    try:
        ortho = rasterio.open(ortho_path)
        dsm = rasterio.open(dsm_path)
        nir = None if nir_path is None else rasterio.open(nir_path)
    except rasterio.errors.RasterioIOError as exc:
        raise InputError(f"{ortho_path} / {dsm_path} / {nir_path}: cannot open ({exc})") from None
    with ExitStack() as stack:
        for ds in (ortho, dsm, nir):
            if ds is not None:
                stack.enter_context(ds)
        if ortho.count < 3:
            raise InputError(f"{ortho_path}: orthophoto needs at least 3 bands (R, G, B), has {ortho.count}")
        _check_grids(ortho, dsm, ortho_path, dsm_path)
        if nir is not None:
            _check_nir(ortho, nir, ortho_path, nir_path)
        if tile_cells < 4 * params.seed_bandwidth_cells:
            raise ValueError(f"tile_cells {tile_cells} must be at least 4 seed band widths ({4 * params.seed_bandwidth_cells} cells)")
        yield ortho, dsm, nir, grid_of(ortho, ortho_path), params.blur_radius_cells + params.slope_window_cells


def histogram_edges(params: ObiaParams) -> np.ndarray:
    """Edges of the global fine histogram: ``FINE_BINS_PER_BIN`` x ``hist_bins`` bins over the index range."""
    return np.linspace(*params.index_range, params.hist_bins * FINE_BINS_PER_BIN + 1)


def global_threshold(hist: IndexHistogram, params: ObiaParams) -> ThresholdResult:
    """The valley threshold of the whole site's fine histogram (:func:`find_bare_threshold`, with the
    one-DN steps where the bands are integers and the mixed-cell test)."""
    thr = find_bare_threshold(hist.counts, histogram_edges(params), params.hist_bins, params.min_class_fraction,
                              params.max_valley_ratio, fine_steps=hist.step_sums if hist.quantised else None,
                              fine_by_range=hist.by_range)
    log.info("global %s threshold: valley %s (valleys %s; one-DN index step below the first %s; %s), Otsu %s (%s)",
             params.index, thr.valley, thr.valleys, thr.index_step, thr.stop_reason, thr.otsu, thr.reason)
    return thr


def band_steps(ortho: DatasetReader, nir: DatasetReader | None) -> tuple[float, float]:
    """One quantisation step of the colour bands and of the NIR band (0 without one or for floats)."""
    return dn_step(ortho.dtypes[0]), 0.0 if nir is None else dn_step(nir.dtypes[0])


def unimodal_code(params: ObiaParams) -> int:
    """Class of every cell when the histogram is not bimodal (0 vegetated, 1 bare)."""
    return 0 if params.unimodal_class == "grass" else 1


def block_histogram(ortho: DatasetReader, dsm: DatasetReader, nir: DatasetReader | None, read: Window, core: Window,
                    params: ObiaParams, src: str, edges: np.ndarray) -> IndexHistogram:
    """Fine histogram of the blurred index over one block's core (``read`` = core + halo), by
    local range, with the cells' summed one-DN index steps.

    Open datasets ``ortho``, ``dsm`` (and ``nir`` or None); cells whose blue band is the
    brightest are left out (:func:`kitegully.obia.indices.blue_dominant`). The histograms of
    all blocks add up to the global one whatever the order (integers). O(block cells).

    Parameters
    ----------
    ortho, dsm : DatasetReader
        The open orthophoto and DSM.
    nir : DatasetReader or None
        The open NIR orthophoto.
    read : Window
        The block's read window (core plus halo).
    core : Window
        The block's core window.
    params : ObiaParams
        Method parameters.
    src : str
        Orthophoto name for error messages.
    edges : ndarray
        Bin edges of the fine histogram (:func:`histogram_edges`).

    Returns
    -------
    IndexHistogram
        Counts by local range (:func:`kitegully.obia.scene.mixing_range`) and one-DN step sums
        (zeros and ``quantised`` False for floating-point bands).
    """
    rgb, dem, valid = _read_tile(ortho, dsm, read)
    nir_band = _read_nir(nir, read, valid)
    _, blur, _ = _tile_index(rgb, nir_band, valid, params, src)
    r0, c0 = core.row_off - read.row_off, core.col_off - read.col_off
    core_of = (slice(r0, r0 + core.height), slice(c0, c0 + core.width))
    inner = blur[core_of]
    counted = np.isfinite(inner) & ~blue_dominant(*(b[core_of] for b in rgb))
    rgb_step, nir_step = band_steps(ortho, nir)
    steps = index_step(*(b[core_of] for b in rgb), params, rgb_step,
                       nir=None if nir_band is None else nir_band[core_of], nir_step=nir_step)
    ranges = mixing_range(blur, params)[core_of]
    quantised = rgb_step > 0 and (params.index == "exg" or nir_step > 0)
    return IndexHistogram.of(inner[counted], steps[counted], ranges[counted], edges, quantised)


def classify_block(ortho: DatasetReader, dsm: DatasetReader, nir: DatasetReader | None, read: Window, core: Window,
                   params: ObiaParams, src: str, cell: float, valley: float | None,
                   unimodal: int) -> tuple[np.ndarray, int]:
    """Segment and classify one block (``read`` = core + halo); the core's classes and its water cells.

    Segments do not cross the block's read window [I]; the result depends only on the block
    and the global threshold ``valley``, so any grouping of blocks into jobs gives the same map.
    O(block cells · log).

    Parameters
    ----------
    ortho, dsm : DatasetReader
        The open orthophoto and DSM.
    nir : DatasetReader or None
        The open NIR orthophoto.
    read : Window
        The block's read window (core plus halo).
    core : Window
        The block's core window.
    params : ObiaParams
        Method parameters.
    src : str
        Orthophoto name for error messages.
    cell : float
        Cell size (m).
    valley : float or None
        Global threshold of the index; None when the histogram is not bimodal.
    unimodal : int
        Class of every segment when ``valley`` is None (:func:`unimodal_code`).

    Returns
    -------
    classes : ndarray (core rows, core cols) uint8
        0 vegetated, 1 bare, 255 no data.
    water_cells : int
        Core cells masked as open water (segments mostly blue-dominant, or of blurred NDVI below
        ``water_ndvi_below``), left unclassified (255).
    """
    rgb, dem, valid = _read_tile(ortho, dsm, read)
    nir_band = _read_nir(nir, read, valid)
    # water is masked per segment here (segment mean of the blurred index below
    # the water value), so that single cells of land whose NDVI dips below it
    # (texture, NIR/RGB co-registration) stay land; the histogram masks cells
    raw, blur = blurred_index(*rgb, valid, params, nir_band, src)
    out = np.full(valid.shape, NODATA, dtype=np.uint8)
    wet = np.zeros(valid.shape, dtype=bool)
    if valid.any():
        seg = segment(rgb[0], rgb[1], rgb[2], dem, cell, valid, params, nir=nir_band)
        segments, nseg = seg.segments, seg.n_segments
        feature = blur if params.segment_feature == "blurred" else raw
        means = segment_means(feature, segments, nseg)
        out = classify_segments(means, segments, valley, unimodal)
        # [I] a segment most of whose cells have blue as their brightest band (open water, shade lit by
        # the blue sky) is neither soil nor plant (indices.blue_dominant): it left the threshold's histogram
        # and is not classified either; on an RGB orthophoto ExG alone would call open water bare soil
        blue = segment_means(blue_dominant(*rgb).astype(np.float32), segments, nseg) > 0.5
        wet = blue[segments] & (segments > 0)
        if params.water_ndvi_below is not None:
            wet |= (segment_means(blur, segments, nseg) < params.water_ndvi_below)[segments] & (segments > 0)
        out[wet] = NODATA
        out = remove_small_eroded(out, cell, params.min_area_m2)
        out[~valid] = NODATA
    r0, c0 = core.row_off - read.row_off, core.col_off - read.col_off
    return out[r0:r0 + core.height, c0:c0 + core.width], int(wet[r0:r0 + core.height, c0:c0 + core.width].sum())


def site_histogram(ortho_path: str | Path, dsm_path: str | Path, params: ObiaParams, tile_cells: int,
                   nir_path: str | Path | None = None) -> IndexHistogram:
    """The whole site's fine histogram of the blurred index, block by block (:func:`block_histogram`).

    Parameters and errors as :func:`bare_soil_map`. O(N) time, memory a few blocks.
    """
    with open_kite_inputs(ortho_path, dsm_path, nir_path, params, tile_cells) as (ortho, dsm, nir, grid, halo):
        hist = IndexHistogram.zeros(params.hist_bins * FINE_BINS_PER_BIN)
        edges = histogram_edges(params)
        tiles = list(iter_tiles(grid, tile_cells, halo))
        for i, (read, core) in enumerate(tiles):
            hist += block_histogram(ortho, dsm, nir, read, core, params, str(ortho_path), edges)
            log.info("histogram: tile %d/%d", i + 1, len(tiles))
    return hist


def bare_soil_map(ortho_path: str | Path, dsm_path: str | Path, out_path: str | Path, params: ObiaParams, tile_cells: int,
                  nir_path: str | Path | None = None, threshold: ThresholdResult | None = None) -> ThresholdResult:
    """Classify a site orthophoto into grass/vegetated (0) and bare (1); 255 = no data.

    Writes a uint8 GeoTIFF on the orthophoto grid and returns the global threshold.
    With a histogram that is not bimodal, every cell gets ``params.unimodal_class``.

    Parameters
    ----------
    ortho_path, dsm_path : path
        RGB orthophoto (bands 1-3) and the DSM (resampled onto the orthophoto's cells).
    out_path : path
        The bare-soil GeoTIFF.
    params : ObiaParams
        Method parameters; ``params.index`` picks ExG or NDVI.
    tile_cells : int
        Tile side (cells); segments do not cross tiles.
    nir_path : path, optional
        NIR orthophoto (band 1) on the RGB orthophoto's grid, where the survey has one: it
        joins the segmentation features and is required by ``index: ndvi``. The returned
        result's ``water_cells`` counts the cells left unclassified as open water (segments
        mostly blue-dominant, or below ``water_ndvi_below``).
    threshold : ThresholdResult, optional
        Classify at this threshold instead of the site's own (evaluation of other thresholds on
        the same orthophoto); its ``water_cells`` is set.

    Raises
    ------
    InputError
        Unreadable files, grids that do not fit, ``index: ndvi`` without ``nir_path``.
    """
    thr = threshold
    if thr is None:
        thr = global_threshold(site_histogram(ortho_path, dsm_path, params, tile_cells, nir_path), params)
    with open_kite_inputs(ortho_path, dsm_path, nir_path, params, tile_cells) as (ortho, dsm, nir, grid, halo):
        src = str(ortho_path)
        tiles = list(iter_tiles(grid, tile_cells, halo))
        water_cells = 0
        unimodal = unimodal_code(params)
        profile = _profile(grid, 1, "uint8", NODATA, cog=True)
        Path(out_path).parent.mkdir(parents=True, exist_ok=True)
        with rasterio.open(out_path, "w", **profile) as dst:
            for i, (read, core) in enumerate(tiles):
                out, wet = classify_block(ortho, dsm, nir, read, core, params, src, grid.cell, thr.valley, unimodal)
                water_cells += wet
                dst.write(out, 1, window=core)
                log.info("classification: tile %d/%d", i + 1, len(tiles))
            dst.descriptions = ("bare_soil (0 vegetated, 1 bare, 255 no data)",)
    thr.water_cells = water_cells
    log.info("open water (segments mostly blue-dominant%s): %d cells not classified", "" if params.water_ndvi_below is None
             else f" or of blurred NDVI < {params.water_ndvi_below:g}", water_cells)
    return thr
