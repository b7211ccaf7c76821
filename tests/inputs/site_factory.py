"""A tiny, valid site on disk (3 JPEGs with EXIF GPS, GCP file, checkpoints, DEM) for input tests."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import piexif
import rasterio
from PIL import Image
from rasterio.transform import from_origin

X0, Y0 = 544500.0, 4083900.0  # UTM 32N (EPSG:32632), near 9.5 E 36.9 N
LON, LAT, CAM_ALT = 9.5, 36.9, 400.0
W, H = 64, 48
GCP_XYZ = [(X0, Y0, 300.0), (X0 + 40, Y0 + 10, 301.5), (X0 + 80, Y0 + 50, 303.0), (X0 + 20, Y0 + 60, 302.0)]
CHECKPOINTS = [("c1", X0 + 30, Y0 + 30, 301.0), ("c2", X0 + 60, Y0 + 20, 302.2), ("c3", X0 + 10, Y0 + 45, 300.7)]


def _rational(v: float, q: int = 10000) -> tuple[int, int]:
    return int(round(v * q)), q


def _dms(deg: float) -> tuple:
    d = int(deg)
    m = int((deg - d) * 60)
    s = (deg - d - m / 60) * 3600
    return ((d, 1), (m, 1), _rational(s, 100))


def write_photo(path: Path, seed: int, model: bytes = b"Canon PowerShot A3300 IS", size: tuple[int, int] = (W, H),
                gps: tuple[float, float, float] | None = (LON, LAT, CAM_ALT), orientation: int = 1) -> Path:
    """A noise JPEG with EXIF make/model, orientation and (optionally) GPS."""
    gps_ifd = {}
    if gps is not None:
        lon, lat, alt = gps
        gps_ifd = {piexif.GPSIFD.GPSLatitudeRef: b"N" if lat >= 0 else b"S", piexif.GPSIFD.GPSLatitude: _dms(abs(lat)),
                   piexif.GPSIFD.GPSLongitudeRef: b"E" if lon >= 0 else b"W", piexif.GPSIFD.GPSLongitude: _dms(abs(lon)),
                   piexif.GPSIFD.GPSAltitudeRef: 0, piexif.GPSIFD.GPSAltitude: _rational(alt, 100)}
    exif = piexif.dump({"0th": {piexif.ImageIFD.Make: b"Canon", piexif.ImageIFD.Model: model,
                                piexif.ImageIFD.Orientation: orientation},
                        "Exif": {}, "GPS": gps_ifd, "1st": {}})
    rng = np.random.default_rng(seed)
    Image.fromarray(rng.integers(0, 255, (size[1], size[0], 3), dtype=np.uint8)).save(path, quality=90, exif=exif)
    return path


def gcp_lines(rows=None, header: str = "EPSG:32632") -> str:
    """ODM gcp_list.txt text: each GCP seen in img_0 and img_1."""
    rows = rows if rows is not None else [
        (x, y, z, 10 + 8 * i, 12 + 5 * i, f"img_{j}.jpg", f"g{i}") for i, (x, y, z) in enumerate(GCP_XYZ) for j in (0, 1)
    ]
    return header + "\n" + "".join(" ".join(str(v) for v in r) + "\n" for r in rows)


def write_dem(path: Path, crs: str | None = "EPSG:32632", res: tuple[float, float] = (1.0, 1.0), nodata=None, fill=None) -> Path:
    data = np.full((20, 20), 300.0, np.float32)
    if fill is not None:
        data[:3, :3] = fill
    profile = dict(driver="GTiff", width=20, height=20, count=1, dtype="float32",
                   transform=from_origin(X0, Y0 + 80, res[0], res[1]))
    if crs:
        profile["crs"] = crs
    if nodata is not None:
        profile["nodata"] = nodata
    with rasterio.open(path, "w", **profile) as ds:
        ds.write(data, 1)
    return path


def write_heads(path: Path, crs: str | None = "EPSG:32632", n: int = 3) -> Path:
    """Gully head points (GeoPackage)."""
    import geopandas as gpd
    from shapely.geometry import Point

    if path.exists():
        path.unlink()
    gdf = gpd.GeoDataFrame({"id": list(range(n))}, geometry=[Point(X0 + 10 * i, Y0 + 20) for i in range(n)], crs=crs)
    gdf.to_file(path, driver="GPKG")
    return path


def make_site(root: Path) -> dict:
    """Write the valid site under ``root``; returns its paths."""
    images = root / "images"
    images.mkdir(parents=True)
    for k in range(3):
        write_photo(images / f"img_{k}.jpg", k)
    gcp = root / "gcp_list.txt"
    gcp.write_text(gcp_lines(), encoding="utf-8")
    cps = root / "checkpoints.csv"
    cps.write_text("id,x,y,z\n" + "".join(f"{i},{x},{y},{z}\n" for i, x, y, z in CHECKPOINTS), encoding="utf-8")
    dem = write_dem(root / "dem.tif")
    heads = write_heads(root / "heads.gpkg")
    out = root / "out"
    out.mkdir()
    return {"root": root, "images": images, "gcp": gcp, "checkpoints": cps, "dem": dem, "heads": heads, "out": out}
