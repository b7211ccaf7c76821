"""DEM sites with bad inputs stop with one clear sentence."""

import numpy as np
import pytest
from change.change_synth import pair, write

from kitegully import InputError
from kitegully.change.dod import load_epoch, on_common_grid
from kitegully.config import load_yaml, validate_config
from kitegully.io.raster import GridSpec


def _epoch(path, **acc):
    return {"name": "e", "dem": str(path), "nodata": None, "accuracy": acc or {"sd_m": 0.05}}


def test_different_crs(tmp_path):
    g, z1, z2, _ = pair()
    a = write(tmp_path / "a.tif", z1, g)
    g2 = GridSpec(g.x0, g.y0, g.cell, g.width, g.height, "EPSG:32631")
    b = write(tmp_path / "b.tif", z2, g2)
    e1, e2 = load_epoch(_epoch(a), "change.epochs[0]"), load_epoch(_epoch(b), "change.epochs[1]")
    with pytest.raises(InputError, match=r"b\.tif: CRS EPSG:32631 differs from .*a\.tif's EPSG:32632"):
        on_common_grid(e1, e2)


def test_site_crs_mismatch(tmp_path):
    g, z1, _, _ = pair()
    a = write(tmp_path / "a.tif", z1, g)
    with pytest.raises(InputError, match="differs from the site CRS EPSG:2180"):
        load_epoch(_epoch(a), "change.epochs[0]", site_crs="EPSG:2180")


def test_non_overlapping(tmp_path):
    g, z1, z2, _ = pair()
    a = write(tmp_path / "a.tif", z1, g)
    far = GridSpec(g.x0 + 5000.0, g.y0, g.cell, g.width, g.height, g.crs)
    b = write(tmp_path / "b.tif", z2, far)
    e1, e2 = load_epoch(_epoch(a), "k0"), load_epoch(_epoch(b), "k1")
    with pytest.raises(InputError, match=r"b\.tif: extent .* does not overlap"):
        on_common_grid(e1, e2)


def test_undeclared_nodata(tmp_path):
    g, z1, _, _ = pair()
    z = z1.copy()
    z[:10, :10] = -9999.0
    a = write(tmp_path / "a.tif", z, g, nodata="none")
    with pytest.raises(InputError, match=r"a\.tif: declares no nodata value but 100 cells hold -9999"):
        load_epoch(_epoch(a), "change.epochs[0]")
    # declared in the site file: accepted and masked
    e = load_epoch({**_epoch(a), "nodata": -9999.0}, "change.epochs[0]")
    assert np.isnan(e.dem.data[:10, :10]).all() and np.isfinite(e.dem.data[10:, 10:]).all()


def test_accuracy_missing(tmp_path):
    g, z1, _, _ = pair()
    a = write(tmp_path / "a.tif", z1, g)
    with pytest.raises(InputError, match=r"change.epochs\[1\] \(.*a\.tif\): no vertical accuracy stated; give one of sd_m"):
        load_epoch({"name": "e", "dem": a, "accuracy": {}}, "change.epochs[1]")
    with pytest.raises(InputError, match="state the vertical accuracy once"):
        load_epoch(_epoch(a, sd_m=0.1, rmse_m=0.1), "k")


def test_missing_file(tmp_path):
    with pytest.raises(InputError, match="nope.tif: DEM file of change.epochs\\[0\\] not found"):
        load_epoch(_epoch(tmp_path / "nope.tif"), "change.epochs[0]")


def test_dem_site_config_is_valid(repo_root):
    site = repo_root / "config" / "sites" / "kamech_dem_change.yaml"
    cfg = {**load_yaml(repo_root / "config" / "config.yaml"), **load_yaml(site)}
    out = validate_config(cfg, sources=[site])
    assert out["change"]["epochs"][1]["accuracy"]["checkpoints"].endswith("checkpoints.csv")


def test_schema_refuses_missing_accuracy(repo_root, tmp_path):
    site = repo_root / "config" / "sites" / "kamech_dem_change.yaml"
    cfg = {**load_yaml(repo_root / "config" / "config.yaml"), **load_yaml(site)}
    del cfg["change"]["epochs"][0]["accuracy"]
    with pytest.raises(InputError, match="change.epochs.0: 'accuracy' is a required property"):
        validate_config(cfg)
