"""Input checks of the gully stage: one clear sentence naming the file on bad input."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Mapping

import numpy as np
import shapely
from pyproj import CRS

from kitegully import InputError
from kitegully.io.vectors import read_vector

if TYPE_CHECKING:
    from kitegully.io.raster import GridSpec


def read_heads(path: str | Path, crs: str) -> tuple[np.ndarray, np.ndarray]:
    """Gully head coordinates (x, y) from a point layer in the site CRS.

    MultiPoints are split into their points. Raises :class:`InputError` if the file has
    no point, or holds other geometry types.
    """
    gdf = read_vector(path, crs=crs)
    geoms = [g for g in gdf.geometry if g is not None and not g.is_empty]
    types = {g.geom_type for g in geoms}
    if not geoms:
        raise InputError(f"{path}: no gully head points in the layer")
    if not types <= {"Point", "MultiPoint"}:
        raise InputError(f"{path}: gully heads must be points, found {', '.join(sorted(types))}")
    pts = shapely.get_coordinates(geoms)
    return pts[:, 0].astype(np.float64), pts[:, 1].astype(np.float64)


def check_dem(dem: np.ndarray, path: str | Path, crs: str | None = None, site_crs: str | None = None) -> None:
    """Raise :class:`InputError` if the DEM has no valid cell or its CRS is not the site CRS.

    Parameters
    ----------
    dem : ndarray (H, W)
        The DEM (m), NaN nodata.
    path : str or Path
        The DEM file, named in the error.
    crs : str or None
        CRS of the DEM; None: not checked.
    site_crs : str or None
        The site CRS; None: not checked.
    """
    if not np.isfinite(dem).any():
        raise InputError(f"{path}: the DEM is all nodata")
    if crs is not None and site_crs is not None and not CRS.from_user_input(crs).equals(CRS.from_user_input(site_crs)):
        raise InputError(f"{path}: CRS {crs} does not match the site CRS {site_crs}")


def check_heads_on_dem(inside: np.ndarray, path: str | Path) -> None:
    """Raise :class:`InputError` if no gully head falls on valid DEM cells."""
    if not np.any(inside):
        raise InputError(f"{path}: none of the {inside.size} gully heads lies on valid DEM cells")


def read_orthophoto_on_grid(path: str | Path, grid: GridSpec) -> np.ndarray:
    """The orthophoto's first three bands (R, G, B) averaged onto ``grid`` (float32, 0 = no data).

    The orthophoto of Stage 5 is made on the DSM's footprint at a finer cell (0.1 m for a
    0.2 m DSM); each DEM cell takes the mean of the orthophoto pixels it covers
    (``rasterio.warp.reproject``, average resampling). Raises :class:`InputError` if the
    file has fewer than three bands. O(n) in orthophoto pixels.
    """
    import rasterio
    from rasterio.warp import Resampling, reproject

    with rasterio.open(path) as src:
        if src.count < 3:
            raise InputError(f"{path}: the orthophoto needs R, G and B bands, found {src.count}")
        out = np.zeros((3, grid.height, grid.width), dtype=np.float32)
        for b in range(3):
            reproject(rasterio.band(src, b + 1), out[b], dst_transform=grid.transform, dst_crs=grid.crs,
                      resampling=Resampling.average, src_nodata=src.nodata if src.nodata is not None else 0, dst_nodata=0)
    return out


def read_tiled_inputs(paths: Mapping[str, str | Path]) -> dict[str, np.ndarray | str | Path]:
    """The tiled jobs' products a large site's gully map takes, as :func:`kitegully.gully.map_gullies` keywords.

    ``paths`` may hold ``smoothed`` and ``depth`` (the merged depth tiles), ``filled`` (the
    tiled fill), ``trace_surface`` (the surface it was made from) and ``crowns`` (the crown
    mask it was made with); absent keys are left out. The fill is read as the float64 the
    map works in (no float32 copy kept beside it) and the tracing surface is passed as its
    path, which the map's fill branch reads and drops: 0.32 GB each at 80 M cells while the
    detector makes its second ground surface, where the rule's memory peaks (session 38).
    """
    from kitegully.io.raster import read_raster

    tiled: dict[str, np.ndarray | str | Path] = {k: read_raster(paths[k])[0] for k in ("smoothed", "depth")
                                                  if k in paths}
    if "filled" in paths:
        tiled["filled"] = read_raster(paths["filled"])[0].astype(np.float64)
    if "trace_surface" in paths:
        tiled["trace_surface"] = paths["trace_surface"]
    if "crowns" in paths:
        tiled["crown_mask"] = read_raster(paths["crowns"])[0] == 1
    return tiled
