"""Rasters handed in (DEMs, orthophotos): CRS present and the site's, square cells, no undeclared nodata sentinels."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import rasterio
from pyproj import CRS
from rasterio.enums import Resampling

from kitegully.inputs.crs import crs_label
from kitegully.inputs.findings import Findings

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


def check_raster(path: str | Path, site_crs: CRS, declared_nodata: float | None, found: Findings, key: str = "inputs.rasters") -> None:
    """Check one raster; record errors in ``found``.

    ``declared_nodata`` is the config's value (``inputs.rasters[].nodata``); the file's own
    nodata tag counts as declared too. The data are read decimated to at most
    ``MAX_SAMPLE_SIDE`` cells a side (nearest neighbour keeps sentinel values intact), so
    the cost is O(MAX_SAMPLE_SIDE²) whatever the raster size.
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
                             f"declare it (nodata in the file or {key}[].nodata) so it is not read as elevation")
            return
        found.facts.setdefault("rasters", []).append({"path": src, "cell_m": rx, "width": ds.width, "height": ds.height})
