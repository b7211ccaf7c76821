"""The gully and polygon stages on a DEM a site hands in (issue 17: "the same entry lets the polygon and
gully stages run on a given DTM"): a LiDAR-like DTM GeoTIFF with a declared nodata value, no photographs.

The DTM is the analytic Y-gully catchment of ``test_gully`` with 3 cm of survey noise, written as a
user's software would: float32, -9999 in the unsurveyed corner, no nodata tag in the file (declared in
the site file instead). A file whose -9999 nobody declared stops at ``check_dem_file`` with one line.
"""

from __future__ import annotations

import copy

import numpy as np
import pandas as pd
import pytest
import rasterio
import yaml

from kitegully.config import load_yaml
from kitegully.io.raster import read_raster
from kitegully.io.vectors import read_vector
from snakemake_utils import REPO, run_snakemake

from .test_gully import CRS, fabricate_twin


def _lidar_dtm(src: str, path, rng_seed: int = 3) -> None:
    """The twin's DTM + 3 cm noise, nodata written as -9999 and NOT tagged in the file."""
    z, grid = read_raster(src)
    z = z + np.random.default_rng(rng_seed).normal(0, 0.03, z.shape)
    z = np.where(np.isfinite(z), z, -9999.0).astype(np.float32)
    with rasterio.open(path, "w", driver="GTiff", width=grid.width, height=grid.height, count=1, dtype="float32",
                       crs=CRS, transform=grid.transform) as dst:
        dst.write(z, 1)


def _site(tmp_path, declare_nodata: bool = True):
    src = tmp_path / "src"
    info = fabricate_twin(src / "twin")
    dtm = tmp_path / "lidar_dtm.tif"
    _lidar_dtm(str(src / "twin" / "truth" / "dtm.tif"), dtm)
    tiny = load_yaml(REPO / "config" / "sites" / "tiny_twin.yaml")
    gully = copy.deepcopy(tiny["gully"])
    gully.update(dem="file", dem_file=str(dtm), dem_nodata=-9999.0 if declare_nodata else None,
                 heads_file=str(src / "twin" / "observed" / "gully_heads.gpkg"),
                 reference_network_file=str(src / "twin" / "observed" / "field_network.gpkg"))
    polygons = copy.deepcopy(tiny["polygons"])
    polygons.update(dem_file=str(dtm), dem_nodata=-9999.0 if declare_nodata else None)
    polygons["breaklines"]["ground_segment_m"] = 0.0  # a ground DTM: no shrub clumps on the rims
    site = dict(site=dict(name="dem_gully", kind="real", crs=CRS,
                          description="LiDAR-like DTM of the analytic Y-gully catchment (test)"),
                seed=1, gully=gully, polygons=polygons)
    path = tmp_path / "dem_gully.yaml"
    path.write_text(yaml.safe_dump(site, sort_keys=False))
    return path, info


@pytest.mark.slow
def test_gully_and_polygons_run_on_a_given_dtm(tmp_path):
    site, info = _site(tmp_path)
    results = tmp_path / "results"
    root = results / "dem_gully"
    targets = [str(root / "gully" / n) for n in ("gully_summary.csv", "network_validation.csv")] + [
        str(root / "polygons" / "morphometry.csv")]
    run_snakemake(site, results, targets, cores=2)
    checked, grid = read_raster(root / "inputs" / "dem" / "gully.tif")
    assert grid == info["grid"] and checked.dtype == np.float32
    assert np.isnan(checked[:40, :60]).all() and np.isfinite(checked[40:, 60:]).all()  # -9999 became nodata
    summary = pd.read_csv(root / "gully" / "gully_summary.csv").set_index("quantity")["value"]
    assert str(tmp_path / "lidar_dtm.tif") in summary["DEM source"]
    val = pd.read_csv(root / "gully" / "network_validation.csv").set_index("category")["percent"]
    assert val["good_fit"] > 85 and val["false_positive"] < 10  # a clean 1.2 m gully on a 3 cm-noise DTM
    polys = read_vector(root / "polygons" / "gully_polygons_t0.5.gpkg", crs=CRS)
    # the V is deeper than t = 0.5 m over 3.5 m of its 6 m width along ~215 m (at most ~750 m²); the fill leaves
    # out what drains freely (the outlet reach, the heads)
    assert 300 < polys.area.sum() < 900
    morph = pd.read_csv(root / "polygons" / "morphometry.csv")
    assert len(morph) >= 1 and morph["max_depth_m"].max() == pytest.approx(1.2, abs=0.3)


def test_undeclared_nodata_in_a_given_dtm_is_one_line(tmp_path):
    site, _ = _site(tmp_path, declare_nodata=False)
    results = tmp_path / "results"
    proc = run_snakemake(site, results, [str(results / "dem_gully" / "gully" / "gully_summary.csv")], check=False)
    assert proc.returncode != 0 and "Traceback" not in proc.stderr
    line = (f"{tmp_path / 'lidar_dtm.tif'}: 2400 cells hold -9999 but the raster declares no such nodata value; declare it "
            "(nodata in the file or gully.dem_nodata) so it is not read as elevation")
    log = results / "dem_gully" / "logs" / "inputs" / "dem_gully.log"
    assert log.read_text().splitlines()[-1] == line
    assert not (results / "dem_gully" / "gully").exists()  # the stage never started


def test_dem_file_without_dem_file_key_is_one_line(tmp_path):
    site, _ = _site(tmp_path)
    cfg = yaml.safe_load(site.read_text())
    cfg["gully"]["dem_file"] = None
    site.write_text(yaml.safe_dump(cfg, sort_keys=False))
    proc = run_snakemake(site, tmp_path / "results", ["-n"], check=False)
    assert proc.returncode != 0
    assert "Invalid configuration: gully.dem: file needs gully.dem_file (a DEM GeoTIFF in the site CRS)" in proc.stdout + proc.stderr
