"""Rasters handed in (DEMs, orthophotos): CRS present and the site's, square cells, no undeclared nodata sentinels."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import rasterio
from pyproj import CRS
from rasterio.enums import Resampling

from kitegully import InputError
from kitegully.inputs.crs import crs_label
from kitegully.inputs.findings import Findings

if TYPE_CHECKING:
    from kitegully.io.raster import GridSpec

# Values that software writes for "no data" when it declares none (ESRI/GDAL, SRTM int16,
# float32 max of ArcGIS): found in the data they are refused unless declared.
SENTINELS = (-9999.0, -32768.0, 3.4e38)
# [I] Relative difference of the x and y cell size still called square.
SQUARE_RTOL = 1e-6
# Cells read per side at most to look for sentinels (a decimated read keeps the check cheap).
MAX_SAMPLE_SIDE = 2048


def _sentinel_hits(data: np.ndarray) -> list[tuple[float, int]]:
    hits = []
    for s in SENTINELS:
        n = int(np.count_nonzero(data >= 3.0e38)) if s > 1e30 else int(np.count_nonzero(data == s))
        if n:
            hits.append((s, n))
    return hits


def check_raster(path: str | Path, site_crs: CRS, declared_nodata: float | None, found: Findings, key: str = "inputs.rasters",
                 nodata_key: str | None = None) -> None:
    """Check one raster; record errors in ``found``.

    ``declared_nodata`` is the config's value (``inputs.rasters[].nodata``, or ``nodata_key``
    where the raster is named elsewhere); the file's own nodata tag counts as declared too. The data are read decimated to at most
    ``MAX_SAMPLE_SIDE`` cells a side (nearest neighbour keeps sentinel values intact), so
    the cost is O(MAX_SAMPLE_SIDE²) whatever the raster size.

    Parameters
    ----------
    path : str or Path
        The raster.
    site_crs : CRS
        The site CRS; the raster's CRS must equal it.
    declared_nodata : float or None
        Nodata value stated in the configuration.
    found : Findings
        Collects the first error, or the raster's cell size (m) and size when it passes.
    key : str
        Config key naming the raster, for the messages.
    nodata_key : str or None
        Config key of ``declared_nodata``, for the messages; None: ``<key>[].nodata``.
    """
    path = Path(path)
    src = str(path)
    if not path.is_file():
        found.error(src, f"raster named in {key} not found")
        return
    try:
        ds = rasterio.open(path)
    except rasterio.errors.RasterioIOError as exc:
        found.error(src, f"not a readable raster ({str(exc).splitlines()[0]})")
        return
    with ds:
        if ds.crs is None:
            found.error(src, f"the raster has no CRS; it must be in the site CRS {crs_label(site_crs)}")
            return
        rcrs = CRS.from_user_input(ds.crs.to_wkt())
        if not rcrs.equals(site_crs, ignore_axis_order=True):
            found.error(src, f"the raster is in {crs_label(rcrs)}, not the site CRS {crs_label(site_crs)}; reproject it first")
            return
        rx, ry = abs(ds.transform.a), abs(ds.transform.e)
        if ds.transform.b or ds.transform.d:
            found.error(src, "the raster grid is rotated; give a north-up grid")
            return
        if abs(rx - ry) > SQUARE_RTOL * max(rx, ry):
            found.error(src, f"cells are not square ({rx:g} x {ry:g} m); resample to square cells")
            return
        declared = [v for v in (ds.nodata, declared_nodata) if v is not None]
        step = max(1, int(np.ceil(max(ds.width, ds.height) / MAX_SAMPLE_SIDE)))
        data = ds.read(1, out_shape=(max(1, ds.height // step), max(1, ds.width // step)), resampling=Resampling.nearest)
        data = data.astype(np.float64)
        hits = [(s, n) for s, n in _sentinel_hits(data)
                if not any(d == s or (s > 1e30 and d >= 3.0e38) for d in declared)]
        if hits:
            s, n = hits[0]
            value = f"{s:g}" if s < 1e30 else "3.4e38 (float32 maximum)"
            found.error(src, f"{n} cells hold {value} but the raster declares no such nodata value; "
                             f"declare it (nodata in the file or {nodata_key or key + '[].nodata'}) so it is not read as elevation")
            return
        found.facts.setdefault("rasters", []).append({"path": src, "cell_m": rx, "width": ds.width, "height": ds.height})


def read_dem_file(path: str | Path, site_crs: str, declared_nodata: float | None, key: str,
                  nodata_key: str | None = None) -> tuple[np.ndarray, GridSpec]:
    """A DEM GeoTIFF a site hands in (LiDAR, TLS, another software's DSM), checked and read as float32.

    Parameters
    ----------
    path : str or Path
        The DEM file.
    site_crs : str
        The site's CRS; the DEM must be in it (projected, metres: the site CRS is checked so).
    declared_nodata : float or None
        Nodata value stated in the configuration; the file's own nodata tag counts too.
    key : str
        Config key naming the file, for the messages (e.g. ``gully.dem_file``).
    nodata_key : str, optional
        Config key of ``declared_nodata`` (messages); default ``<key's section>.dem_nodata``.

    Returns
    -------
    data : ndarray float32 (rows, cols)
        Elevations (m), NaN where the file or the configuration says nodata.
    grid : GridSpec

    Raises
    ------
    InputError
        One sentence naming the file: missing, unreadable, no CRS or another CRS, rotated grid,
        non-square cells, nodata sentinels nobody declared, or no valid elevation.

    Notes
    -----
    Cost: one decimated read for the checks (O(MAX_SAMPLE_SIDE²)) and one full read, O(cells).
    """
    from kitegully.inputs.crs import site_crs as parse_site_crs
    from kitegully.io.raster import grid_of

    path = Path(path)
    found = Findings()
    check_raster(path, parse_site_crs(site_crs), declared_nodata, found, key=key,
                 nodata_key=nodata_key or f"{key.rsplit('.', 1)[0]}.dem_nodata")
    found.raise_for_errors()
    with rasterio.open(path) as ds:
        grid = grid_of(ds, path)
        data = ds.read(1).astype(np.float32)
        for v in (ds.nodata, declared_nodata):
            if v is not None and not np.isnan(v):
                data[data == np.float32(v)] = np.nan
    if not np.isfinite(data).any():
        raise InputError(f"{path}: the DEM named in {key} holds no valid elevation")
    return data, grid
