"""Products are Cloud-Optimised GeoTIFFs; the orthophoto carries a mask band, not 0 as nodata."""

from __future__ import annotations

import numpy as np
import pytest
import rasterio
from rasterio.enums import MaskFlags
from rio_cogeo.cogeo import cog_validate

from kitegully.io.raster import GridSpec, Raster, _profile, write_raster

GRID = GridSpec(578800.0, 4081700.0, 0.1, 1100, 700, "EPSG:32632")


def _dsm() -> np.ndarray:
    rng = np.random.default_rng(3)
    rr, cc = np.mgrid[0:GRID.height, 0:GRID.width]
    z = (120.0 + 0.01 * rr + 2.0 * np.sin(cc / 50.0) + rng.normal(0, 0.02, rr.shape)).astype(np.float32)
    z[:40, :] = np.nan
    z[300:320, 500:560] = np.nan
    return z


def _legacy_write(path, arr, grid, nodata):
    """The former writer (plain tiled GTiff), to show that only the container changed."""
    arr = arr if arr.ndim == 3 else arr[None]
    with rasterio.open(path, "w", **_profile(grid, arr.shape[0], arr.dtype.name, nodata)) as dst:
        dst.write(arr)


def test_dsm_is_a_valid_cog_with_overviews_and_identical_values(tmp_path):
    z = _dsm()
    Raster(z, GRID).write(tmp_path / "dsm.tif", tags={"units": "m"})
    ok, errors, warnings = cog_validate(tmp_path / "dsm.tif", quiet=True)
    assert ok and not errors and not warnings, (errors, warnings)
    with rasterio.open(tmp_path / "dsm.tif") as src:
        assert src.driver == "GTiff" and src.block_shapes[0] == (256, 256)
        assert src.compression.name.lower() == "deflate"
        assert src.overviews(1) == [2, 4, 8]  # halving until 1100 columns fit one 256-cell tile
        assert np.isnan(src.nodata) and src.dtypes[0] == "float32" and src.tags()["units"] == "m"
    _legacy_write(tmp_path / "legacy.tif", z, GRID, float("nan"))
    new, old = Raster.read(tmp_path / "dsm.tif"), Raster.read(tmp_path / "legacy.tif")
    np.testing.assert_array_equal(new.data, old.data)  # NaN in the same cells, bit-identical values
    np.testing.assert_array_equal(new.data, z)
    assert new.grid == old.grid == GRID


def test_orthophoto_mask_band_replaces_zero_nodata(tmp_path):
    rng = np.random.default_rng(4)
    img = rng.integers(1, 256, (3, GRID.height, GRID.width), dtype=np.uint8)
    seen = np.ones((GRID.height, GRID.width), bool)
    seen[:, :90] = False
    seen[500:, 900:] = False
    img[:, ~seen] = 0
    write_raster(tmp_path / "ortho.tif", img, GRID, band_names=["R", "G", "B"], mask=seen, overview_resampling="average")
    ok, errors, warnings = cog_validate(tmp_path / "ortho.tif", quiet=True)
    assert ok and not errors and not warnings, (errors, warnings)
    with rasterio.open(tmp_path / "ortho.tif") as src:
        assert src.nodata is None and src.descriptions == ("R", "G", "B")
        assert all(flags == [MaskFlags.per_dataset] for flags in src.mask_flag_enums)
        np.testing.assert_array_equal(src.dataset_mask() > 0, seen)
        np.testing.assert_array_equal(src.read(), img)  # the written values are unchanged
        assert src.overviews(1) == [2, 4, 8]
    _legacy_write(tmp_path / "legacy.tif", img, GRID, 0)
    np.testing.assert_array_equal(Raster.read(tmp_path / "ortho.tif", band=None).data,
                                  Raster.read(tmp_path / "legacy.tif", band=None).data)


def test_class_raster_keeps_its_codes_in_the_overviews(tmp_path):
    cls = np.zeros((GRID.height, GRID.width), np.uint8)
    cls[::2, ::2] = 1
    cls[:50] = 255
    write_raster(tmp_path / "classes.tif", cls, GRID, nodata=255)
    assert cog_validate(tmp_path / "classes.tif", quiet=True)[0]
    with rasterio.open(tmp_path / "classes.tif") as src:
        over = src.read(1, out_shape=(GRID.height // 4, GRID.width // 4))
        assert src.nodata == 255
    assert set(np.unique(over)) <= {0, 1, 255}  # nearest, not averaged into new codes


def test_small_raster_is_still_a_valid_cog(tmp_path):
    g = GridSpec(0.0, 100.0, 1.0, 40, 30, "EPSG:32632")
    write_raster(tmp_path / "small.tif", np.ones((30, 40), np.float32), g)
    assert cog_validate(tmp_path / "small.tif", quiet=True)[0]
    np.testing.assert_array_equal(Raster.read(tmp_path / "small.tif").data, np.ones((30, 40), np.float32))


@pytest.mark.parametrize("dtype, kw", [
    (np.float32, {}),
    (np.uint8, {"nodata": 255}),
    (np.int32, {"nodata": 0, "overview_resampling": "mode"}),
    (np.float64, {"band_names": ["a", "b"], "tags": {"source": "test"}}),
])
def test_write_raster_gives_the_bytes_of_rasterios_cog_writer(tmp_path, dtype, kw):
    """write_raster copies a MEM dataset with rasterio.shutil.copy (GDAL compresses without
    Python's GIL, session 9): the file is byte for byte what rasterio's COG writer makes."""
    from kitegully.io.raster import _profile

    grid = GridSpec(500000.0, 4100000.0, 0.5, 700, 513, "EPSG:32632")
    rng = np.random.default_rng(3)
    shape = (2, 513, 700) if "band_names" in kw else (513, 700)
    data = (rng.normal(size=shape) * 5).astype(dtype)
    if np.dtype(dtype).kind == "f":
        data[..., 10:20, 30:90] = np.nan
    write_raster(tmp_path / "new.tif", data, grid, **kw)
    arr = data if data.ndim == 3 else data[None]
    nodata = kw.get("nodata", float("nan") if np.dtype(dtype).kind == "f" else None)
    profile = _profile(grid, arr.shape[0], arr.dtype.name, nodata, cog=True)
    if "overview_resampling" in kw:
        profile["overview_resampling"] = kw["overview_resampling"]
    with rasterio.open(tmp_path / "old.tif", "w", **profile) as dst:  # the former way
        dst.write(arr)
        if "band_names" in kw:
            dst.descriptions = tuple(kw["band_names"])
        if "tags" in kw:
            dst.update_tags(**kw["tags"])
    assert (tmp_path / "new.tif").read_bytes() == (tmp_path / "old.tif").read_bytes()
