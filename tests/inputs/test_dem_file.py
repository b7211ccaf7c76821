"""A DEM file a site hands to the gully or polygon stage (``read_dem_file``): checked, read as float32 with NaN."""

from __future__ import annotations

import numpy as np
import pytest
import rasterio
from rasterio.transform import from_origin

from kitegully import InputError
from kitegully.inputs.rasters import read_dem_file

CRS = "EPSG:32632"


def _write(path, data, crs=CRS, nodata=None, cell=(0.5, 0.5)):
    with rasterio.open(path, "w", driver="GTiff", width=data.shape[1], height=data.shape[0], count=1, dtype=data.dtype,
                       crs=crs, transform=from_origin(600000.0, 4100000.0, *cell), nodata=nodata) as dst:
        dst.write(data, 1)
    return str(path)


def test_an_int16_dem_with_its_nodata_tag_becomes_float_with_nan(tmp_path):
    z = np.full((20, 30), 312, np.int16)
    z[:3, :4] = -32768
    data, grid = read_dem_file(_write(tmp_path / "srtm.tif", z, nodata=-32768), CRS, None, "gully.dem_file")
    assert data.dtype == np.float32 and np.isnan(data[:3, :4]).all() and (data[3:, :] == 312).all()
    assert grid.cell == 0.5 and grid.width == 30


def test_a_declared_nodata_value_is_applied(tmp_path):
    z = np.full((20, 30), 41.5, np.float32)
    z[5, 5] = -9999.0
    data, _ = read_dem_file(_write(tmp_path / "lidar.tif", z), CRS, -9999.0, "polygons.dem_file")
    assert np.isnan(data[5, 5]) and np.isfinite(data).sum() == 20 * 30 - 1


@pytest.mark.parametrize("case, message", [
    ("undeclared", r"lidar.tif: 1 cells hold -9999 but the raster declares no such nodata value; declare it \(nodata in the "
                   r"file or gully.dem_nodata\) so it is not read as elevation"),
    ("other_crs", r"lidar.tif: the raster is in .*32631.*, not the site CRS .*32632.*; reproject it first"),
    ("no_crs", r"lidar.tif: the raster has no CRS; it must be in the site CRS"),
    ("oblong_cells", r"lidar.tif: cells are not square \(0.5 x 1 m\); resample to square cells"),
    ("all_nodata", r"lidar.tif: the DEM named in gully.dem_file holds no valid elevation"),
    ("missing", r"lidar.tif: raster named in gully.dem_file not found"),
])
def test_bad_dem_files_are_one_sentence(tmp_path, case, message):
    z = np.full((20, 30), 41.5, np.float32)
    kw = {}
    if case == "undeclared":
        z[5, 5] = -9999.0
    elif case == "other_crs":
        kw["crs"] = "EPSG:32631"
    elif case == "no_crs":
        kw["crs"] = None
    elif case == "oblong_cells":
        kw["cell"] = (0.5, 1.0)
    elif case == "all_nodata":
        z[:] = -9999.0
        kw["nodata"] = -9999.0
    path = tmp_path / "lidar.tif"
    if case != "missing":
        _write(path, z, **kw)
    with pytest.raises(InputError, match=message):
        read_dem_file(path, CRS, None, "gully.dem_file")


def test_a_geographic_site_crs_is_refused_before_the_file_is_read(tmp_path):
    with pytest.raises(InputError, match="is geographic"):
        read_dem_file(_write(tmp_path / "lidar.tif", np.ones((4, 4), np.float32)), "EPSG:4326", None, "gully.dem_file")
