"""The site's QGIS project: plain XML that a real parser opens, every layer path exists."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import geopandas as gpd
import numpy as np
import pandas as pd
import pytest
from shapely.geometry import LineString, Polygon

from kitegully.io.qgis import layer_paths, write_qgis_project
from kitegully.io.raster import GridSpec, write_raster
from kitegully.io.vectors import write_vector

CRS = "EPSG:32632"
GRID = GridSpec(578800.0, 4081700.0, 0.5, 400, 300, CRS)


@pytest.fixture()
def site(tmp_path):
    root = tmp_path / "results" / "demo"
    z = (120 + np.add.outer(np.arange(300) * 0.05, np.sin(np.arange(400) / 20.0))).astype(np.float32)
    z[:10] = np.nan
    write_raster(root / "dense" / "dsm.tif", z, GRID)
    rgb = np.full((3, 600, 800), 120, np.uint8)
    seen = np.ones((600, 800), bool)
    seen[:20] = False
    rgb[:, ~seen] = 0
    write_raster(root / "dense" / "orthophoto.tif", rgb, GridSpec(GRID.x0, GRID.y0, 0.25, 800, 600, CRS), mask=seen)
    write_raster(root / "obia" / "kite" / "bare_soil.tif", (z > 125).astype(np.uint8), GRID, nodata=255)
    x0, y0 = GRID.x0, GRID.y0
    write_vector(gpd.GeoDataFrame({"order": [1]}, geometry=[LineString([(x0 + 10, y0 - 10), (x0 + 150, y0 - 120)])], crs=CRS),
                 root / "gully" / "gully_network.gpkg")
    write_vector(gpd.GeoDataFrame({"area_m2": [50.0]}, geometry=[Polygon([(x0 + 20, y0 - 20), (x0 + 40, y0 - 20), (x0 + 40, y0 - 40)])], crs=CRS),
                 root / "gully" / "gully_polygons.gpkg")
    pd.DataFrame({"id": ["c1", "c2", "c3"], "x_m": [x0 + 5, x0 + 50, x0 + 100], "y_m": [y0 - 5, y0 - 50, y0 - 100],
                  "z_ref_m": [120.0, 121.0, 122.0], "z_model_m": [120.1, np.nan, 121.7],
                  "error_m": [0.1, np.nan, -0.3]}).to_csv(root / "validate_errors.csv", index=False)
    products = {
        "dsm": root / "dense" / "dsm.tif", "orthophoto": root / "dense" / "orthophoto.tif",
        "gully_network": root / "gully" / "gully_network.gpkg", "gully_polygons": root / "gully" / "gully_polygons.gpkg",
        "bare_soil": root / "obia" / "kite" / "bare_soil.tif", "checkpoint_errors": root / "validate_errors.csv",
    }
    return root, products


def test_project_opens_with_a_real_xml_parser_and_every_layer_path_exists(site):
    root, products = site
    qgs = root / "demo.qgs"
    write_qgis_project(qgs, "demo", CRS, products, error_limit_m=0.5, checkpoint_gpkg=root / "report" / "checkpoint_errors.gpkg")
    doc = ET.parse(qgs).getroot()
    assert doc.tag == "qgis" and doc.get("projectname") == "demo"
    assert doc.findtext("projectCrs/spatialrefsys/authid") == CRS
    assert doc.findtext("properties/Paths/Absolute") == "false"
    layers = {ml.findtext("id"): ml for ml in doc.iter("maplayer")}
    assert list(layers) == ["checkpoint_errors", "gully_network", "gully_polygons", "bare_soil", "hillshade", "dsm", "orthophoto"]
    tree_ids = [n.get("id") for n in doc.iter("layer-tree-layer")]
    assert tree_ids == list(layers)
    for ml in layers.values():
        src = ml.findtext("datasource")
        assert src.startswith("./"), src  # relative: the results folder can move
        assert ml.findtext("srs/spatialrefsys/authid") == CRS
    paths = layer_paths(qgs)
    assert len(paths) == 7 and all(p.exists() for p in paths), [p for p in paths if not p.exists()]
    assert {p.name for p in paths} == {"checkpoint_errors.gpkg", "gully_network.gpkg", "gully_polygons.gpkg",
                                       "bare_soil.tif", "dsm.tif", "orthophoto.tif"}
    # styles: terrain ramp on the DSM, hillshade renderer on the same file, diverging errors
    dsm_r = layers["dsm"].find("pipe/rasterrenderer")
    assert dsm_r.get("type") == "singlebandpseudocolor"
    items = dsm_r.findall("rastershader/colorrampshader/item")
    assert len(items) == 9 and float(items[0].get("value")) < float(items[-1].get("value"))
    hs = layers["hillshade"].find("pipe/rasterrenderer")
    assert hs.get("type") == "hillshade" and hs.get("azimuth") == "315.0"
    assert layers["hillshade"].findtext("datasource") == layers["dsm"].findtext("datasource")
    assert layers["orthophoto"].find("pipe/rasterrenderer").get("type") == "multibandcolor"
    assert layers["bare_soil"].find("pipe/rasterrenderer").get("type") == "paletted"
    err = layers["checkpoint_errors"].find("renderer-v2")
    assert err.get("type") == "graduatedSymbol" and err.get("attr") == "error_m"
    bounds = [(float(r.get("lower")), float(r.get("upper"))) for r in err.iter("range")]
    assert bounds[2][1] == 0.0 and bounds[1] == (-0.5, -0.25) and bounds[4] == (0.25, 0.5)  # centred on 0
    colours = [s.find("layer/Option/Option[@name='color']").get("value") for s in err.find("symbols")]
    r0, _, b0 = (int(v) for v in colours[0].split(",")[:3])
    r5, _, b5 = (int(v) for v in colours[-1].split(",")[:3])
    assert b0 > r0 and r5 > b5  # blue below, red above
    pts = gpd.read_file(root / "report" / "checkpoint_errors.gpkg")
    assert len(pts) == 3 and pts.crs.to_string() == CRS and np.isnan(pts["error_m"].iloc[1])


def test_only_the_products_a_site_makes_are_listed(site):
    root, products = site
    qgs = root / "demo.qgs"
    write_qgis_project(qgs, "demo", CRS, {k: products[k] for k in ("gully_network", "gully_polygons")})
    ids = [ml.findtext("id") for ml in ET.parse(qgs).getroot().iter("maplayer")]
    assert ids == ["gully_network", "gully_polygons"]
    assert all(p.exists() for p in layer_paths(qgs))


def test_further_products_are_listed_unticked_with_their_styles(site, tmp_path):
    import laspy

    root, products = site
    x0, y0 = GRID.x0, GRID.y0
    dod = np.sin(np.arange(400)[None, :] / 30.0) * np.ones((300, 1), np.float32) - 0.2
    write_raster(root / "change" / "dod.tif", dod.astype(np.float32), GRID)
    write_raster(root / "change" / "stable_ground.tif", (dod > 0).astype(np.uint8), GRID, nodata=255)
    write_vector(gpd.GeoDataFrame({"width_m": [3.0]}, geometry=[LineString([(x0 + 30, y0 - 30), (x0 + 40, y0 - 35)])], crs=CRS),
                 root / "polygons" / "cross_sections.gpkg")
    write_vector(gpd.GeoDataFrame({"area_m2": [50.0]}, geometry=[Polygon([(x0 + 20, y0 - 20), (x0 + 40, y0 - 20), (x0 + 40, y0 - 40)])], crs=CRS),
                 root / "polygons" / "gully_polygons_t0.5.gpkg")
    header = laspy.LasHeader(point_format=3, version="1.4")
    header.offsets, header.scales = [x0, y0 - 150, 0.0], [0.001] * 3
    las = laspy.LasData(header)
    las.x, las.y, las.z = x0 + np.arange(10.0), y0 - np.arange(10.0), 120 + np.zeros(10)
    (root / "georef").mkdir(parents=True, exist_ok=True)
    las.write(root / "georef" / "sparse_cloud.laz")
    further = {"dod": root / "change" / "dod.tif", "dod_thresholded_probabilistic": root / "change" / "dod.tif",
               "stable_ground": root / "change" / "stable_ground.tif", "cross_sections": root / "polygons" / "cross_sections.gpkg",
               "hoefle_polygons_t0.5": root / "polygons" / "gully_polygons_t0.5.gpkg",
               "sparse_cloud": root / "georef" / "sparse_cloud.laz", "orthophoto_epoch2": products["orthophoto"]}
    qgs = root / "demo.qgs"
    write_qgis_project(qgs, "demo", CRS, {**products, **further}, checkpoint_gpkg=root / "report" / "cp.gpkg")
    doc = ET.parse(qgs).getroot()
    layers = {ml.findtext("id"): ml for ml in doc.iter("maplayer")}
    assert list(layers)[7:] == list(further)
    ticked = {n.get("id"): n.get("checked") for n in doc.iter("layer-tree-layer")}
    assert all(ticked[k] == "Qt::Unchecked" for k in further) and ticked["dsm"] == "Qt::Checked"
    assert all(p.exists() for p in layer_paths(qgs))
    # the DoD on a diverging ramp centred on 0: symmetric limits, white-ish middle
    items = layers["dod"].findall("pipe/rasterrenderer/rastershader/colorrampshader/item")
    lo, hi = float(items[0].get("value")), float(items[-1].get("value"))
    assert lo == -hi and hi > 0.5 and float(items[4].get("value")) == 0.0
    assert "Höfle" in layers["hoefle_polygons_t0.5"].findtext("layername")
    assert layers["sparse_cloud"].get("type") == "point-cloud" and layers["sparse_cloud"].findtext("provider") == "pdal"
    assert layers["stable_ground"].find("pipe/rasterrenderer").get("type") == "paletted"
    assert layers["cross_sections"].find("renderer-v2/symbols/symbol").get("type") == "line"
    with pytest.raises(ValueError, match="unknown product key"):
        write_qgis_project(qgs, "demo", CRS, {**products, "mystery": root / "change" / "dod.tif"}, checkpoint_gpkg=root / "report" / "cp.gpkg")
