"""Kite-scale application: bare-soil map of a site-wide orthophoto + DSM, in tiles.

The histogram (and so the valley threshold) is global: blurred ExG is accumulated tile
by tile into one fixed-range histogram.  Segmentation and classification then run per
tile (segments do not cross tile borders [I]); the tile core is written to the output.
Memory: a few tile-sized arrays.  Cost: O(N log T) for N cells and tiles of T cells.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import rasterio
from rasterio.enums import Resampling
from rasterio.warp import reproject

from kitegully import InputError
from kitegully.io.raster import _profile, grid_of, iter_tiles
from kitegully.obia.classify import NODATA, classify_segments, remove_small_eroded, segment_means
from kitegully.obia.indices import EXG_RANGE
from kitegully.obia.scene import ObiaParams, blurred_exg, segment
from kitegully.obia.threshold import ThresholdResult, find_thresholds

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


def bare_soil_map(ortho_path: str | Path, dsm_path: str | Path, out_path: str | Path, params: ObiaParams, tile_cells: int) -> ThresholdResult:
    """Classify a site orthophoto into grass/vegetated (0) and bare (1); 255 = no data.

    Writes a uint8 GeoTIFF on the orthophoto grid and returns the global threshold.
    With a histogram that is not bimodal, every cell gets ``params.unimodal_class``.
    """
    try:
        ortho = rasterio.open(ortho_path)
        dsm = rasterio.open(dsm_path)
    except rasterio.errors.RasterioIOError as exc:
        raise InputError(f"{ortho_path} / {dsm_path}: cannot open ({exc})") from None
    with ortho, dsm:
        if ortho.count < 3:
            raise InputError(f"{ortho_path}: orthophoto needs at least 3 bands (R, G, B), has {ortho.count}")
        _check_grids(ortho, dsm, ortho_path, dsm_path)
        if tile_cells < 4 * params.seed_bandwidth_cells:
            raise ValueError(f"tile_cells {tile_cells} must be at least 4 seed band widths ({4 * params.seed_bandwidth_cells} cells)")
        grid = grid_of(ortho, ortho_path)
        halo = params.blur_radius_cells + params.slope_window_cells
        counts = np.zeros(params.hist_bins, dtype=np.int64)
        edges = np.linspace(EXG_RANGE[0], EXG_RANGE[1], params.hist_bins + 1)
        tiles = list(iter_tiles(grid, tile_cells, halo))
        for i, (read, core) in enumerate(tiles):
            rgb, dem, valid = _read_tile(ortho, dsm, read)
            _, blur = blurred_exg(*rgb, valid, params)
            r0, c0 = core.row_off - read.row_off, core.col_off - read.col_off
            inner = blur[r0:r0 + core.height, c0:c0 + core.width]
            counts += np.histogram(inner[np.isfinite(inner)], bins=edges)[0]
            log.info("histogram: tile %d/%d", i + 1, len(tiles))
        centres = 0.5 * (edges[:-1] + edges[1:])
        thr = find_thresholds(counts, centres, params.min_class_fraction, params.max_valley_ratio)
        log.info("global threshold: valley %s, Otsu %s (%s)", thr.valley, thr.otsu, thr.reason)
        unimodal = 0 if params.unimodal_class == "grass" else 1
        profile = _profile(grid, 1, "uint8", NODATA, cog=True)
        Path(out_path).parent.mkdir(parents=True, exist_ok=True)
        with rasterio.open(out_path, "w", **profile) as dst:
            for i, (read, core) in enumerate(tiles):
                rgb, dem, valid = _read_tile(ortho, dsm, read)
                out = np.full(valid.shape, NODATA, dtype=np.uint8)
                if valid.any():
                    seg = segment(rgb[0], rgb[1], rgb[2], dem, grid.cell, valid, params)
                    segments, nseg = seg.segments, seg.n_segments
                    exg, exg_blur = blurred_exg(*rgb, valid, params)
                    feature = exg_blur if params.segment_feature == "blurred" else exg
                    means = segment_means(feature, segments, nseg)
                    out = remove_small_eroded(classify_segments(means, segments, thr.valley, unimodal), grid.cell, params.min_area_m2)
                    out[~valid] = NODATA
                r0, c0 = core.row_off - read.row_off, core.col_off - read.col_off
                dst.write(out[r0:r0 + core.height, c0:c0 + core.width], 1, window=core)
                log.info("classification: tile %d/%d", i + 1, len(tiles))
            dst.descriptions = ("bare_soil (0 vegetated, 1 bare, 255 no data)",)
    return thr
