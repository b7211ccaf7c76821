"""Vectors: GeoPackage in the site CRS."""

from __future__ import annotations

from pathlib import Path

import geopandas as gpd

from kitegully import InputError


def write_vector(gdf: gpd.GeoDataFrame, path: str | Path, layer: str | None = None) -> None:
    """Write a GeoDataFrame to a GeoPackage (overwriting), creating the folder.

    Parameters
    ----------
    gdf : GeoDataFrame
        The layer; it must have a CRS (ValueError otherwise).
    path : str or Path
        Output GeoPackage; an existing file is deleted first.
    layer : str or None
        Layer name; None = the file name without its suffix.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if gdf.crs is None:
        raise ValueError(f"{path}: refusing to write a vector layer without a CRS")
    if path.exists():
        path.unlink()
    gdf.to_file(path, driver="GPKG", layer=layer or path.stem)


def read_vector(path: str | Path, crs: str | None = None) -> gpd.GeoDataFrame:
    """Read a vector file; with ``crs``, check it matches and raise :class:`InputError` if not."""
    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: file not found")
    try:
        gdf = gpd.read_file(path)
    except Exception as exc:  # pyogrio raises several types for corrupt files
        raise InputError(f"{path}: cannot read vector file ({exc})") from None
    if crs is not None:
        if gdf.crs is None:
            raise InputError(f"{path}: layer has no CRS; expected {crs}")
        if not gdf.crs.equals(crs):
            raise InputError(f"{path}: CRS {gdf.crs.to_string()} does not match the site CRS {crs}")
    return gdf
