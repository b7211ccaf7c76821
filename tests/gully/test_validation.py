"""The network scoring protocol (kitegully.gully.validation.score_network) on constructed networks."""

from __future__ import annotations

import geopandas as gpd
import numpy as np
import pytest
from shapely import LineString, box

from kitegully import InputError
from kitegully.evaluate.network import NetworkScorer, footprint, scored_reference
from kitegully.gully.validation import (
    SCORED,
    UNFILTERED,
    ValidationParams,
    catchment_outline,
    check_reference,
    score_network,
    score_networks,
)
from kitegully.io.raster import GridSpec

CRS = "EPSG:32632"
GRID = GridSpec(0.0, 100.0, 1.0, 200, 200, CRS)  # x 0..200, y -100..100


def _valid():
    valid = np.ones((GRID.height, GRID.width), dtype=bool)
    valid[:, 150:] = False  # x >= 150 off the DEM
    return valid


def _networks():
    # main channel from a head off the DEM (x = 180) down to x = 0; a tributary with its
    # head on the DEM joins at x = 60; the extracted network follows the tributary and the
    # main channel below it, 1 m off, plus a 20 m spur
    main = LineString([(180, 0), (0, 0)])
    trib = LineString([(60, 60), (60, 0.5)])
    ref = gpd.GeoDataFrame(geometry=[main, trib], crs=CRS)
    ext = gpd.GeoDataFrame(
        geometry=[LineString([(61, 60), (61, 1), (2, 1)]), LineString([(100, 50), (100, 70)])], crs=CRS
    )
    return ref, ext


def test_score_network_is_the_protocol_step_by_step():
    ref, ext = _networks()
    params = ValidationParams(tolerance_m=5.0, extra_tolerances_m=(2.0, 15.0, 5.0), reference_join_m=3.0)
    res = score_network(ref, ext, _valid(), GRID, params)
    # the same steps by hand
    domain = footprint(_valid(), GRID, near=[*ref.geometry, *ext.geometry])
    scored, not_scored, counts = scored_reference(ref, domain, 3.0)
    assert res.counts == counts == {"heads": 2, "heads_on_dem": 1, "pieces": 3, "pieces_scored": 2}
    assert res.scored.length == pytest.approx(scored.length) == pytest.approx(60 + 59.5)
    expected = NetworkScorer([scored], domain, reference_all=ref).score(ext, 5.0)
    assert np.allclose(res.table["length_m"], expected["length_m"])
    pct = res.percent()
    assert pct["good_fit"] + pct["false_negative"] == pytest.approx(100)
    assert pct["false_positive"] == pytest.approx(20 / scored.length * 100)  # the spur only
    # tolerance table: every tolerance once, ascending, both reference sets
    assert params.tolerances_m == [2.0, 5.0, 15.0]
    tol = res.tolerances
    assert list(tol.columns) == ["tolerance_m", "reference_lines", "category", "length_m", "percent"]
    assert sorted(set(tol["tolerance_m"])) == [2.0, 5.0, 15.0] and set(tol["reference_lines"]) == {SCORED, UNFILTERED}
    at5 = tol[(tol["tolerance_m"] == 5.0) & (tol["reference_lines"] == SCORED)]
    assert np.allclose(at5["length_m"], res.table["length_m"])
    unf = tol[(tol["tolerance_m"] == 5.0) & (tol["reference_lines"] == UNFILTERED)].set_index("category")
    # unfiltered: the reach above the tributary (x 60..150 on the DEM) counts as missed
    assert unf.loc["reference", "length_m"] > res.table["length_m"].iloc[0] + 80
    assert set(res.pieces) == {"good_fit", "false_negative", "false_positive", "not_scored"}


def test_score_network_clips_to_the_catchment():
    ref, ext = _networks()
    params = ValidationParams(5.0, (), 3.0)
    whole = score_network(ref, ext, _valid(), GRID, params, geometries=False)
    clipped = score_network(ref, ext, _valid(), GRID, params, catchment=box(0, -10, 200, 40), geometries=False)
    assert whole.pieces == {} and clipped.pieces == {}
    # the tributary above y = 40 and the spur (y 50..70) leave the score
    assert clipped.table["length_m"].iloc[0] == pytest.approx(whole.table["length_m"].iloc[0] - 20, abs=0.01)
    assert clipped.percent()["false_positive"] == pytest.approx(0.0)
    assert clipped.extracted.total_bounds[3] <= 40 + 1e-9


def test_validation_params_from_config_and_checks():
    p = ValidationParams.from_config(
        {"tolerance_m": 5, "extra_tolerances_m": [15, 2], "reference_join_m": 3, "catchment_file": None}
    )
    assert p == ValidationParams(5.0, (15.0, 2.0), 3.0) and p.tolerances_m == [2.0, 5.0, 15.0]
    with pytest.raises(InputError, match="^gully.validation: .*reference_join_m"):
        ValidationParams.from_config({"tolerance_m": 5, "extra_tolerances_m": []})
    with pytest.raises(InputError, match="^gully.validation: .*tolerance"):
        ValidationParams.from_config({"tolerance_m": 5, "extra_tolerances_m": [], "reference_join_m": 3, "tolerance": 1})
    with pytest.raises(ValueError, match="tolerances must be >= 0"):
        ValidationParams(-1.0, (), 3.0)
    with pytest.raises(ValueError, match="reference_join_m must be >= 0"):
        ValidationParams(5.0, (), -3.0)


def test_input_checks_name_the_file():
    polys = gpd.GeoDataFrame(geometry=[box(0, 0, 1, 1)], crs=CRS)
    lines = gpd.GeoDataFrame(geometry=[LineString([(0, 0), (1, 1)])], crs=CRS)
    with pytest.raises(InputError, match="^ref.gpkg: the reference network must hold lines$"):
        check_reference(polys, "ref.gpkg")
    with pytest.raises(InputError, match="^ref.gpkg: the reference network must hold lines$"):
        check_reference(lines.iloc[:0], "ref.gpkg")
    assert check_reference(lines, "ref.gpkg") is lines
    with pytest.raises(InputError, match="^cat.gpkg: the catchment must hold polygons$"):
        catchment_outline(lines, "cat.gpkg")
    assert catchment_outline(polys, "cat.gpkg").area == pytest.approx(1.0)


def test_score_gully_areas_leaves_cells_off_the_dem_out():
    from shapely import box as sbox

    from kitegully.gully.validation import score_gully_areas

    grid = GridSpec(0.0, 10.0, 1.0, 10, 10, CRS)
    truth = gpd.GeoDataFrame(geometry=[sbox(0, 0, 4, 10)], crs=CRS)  # columns 0-3
    gully = np.zeros((10, 10), dtype=np.uint8)
    gully[:, 2:6] = 1  # columns 2-5: half right
    gully[:5, 0] = 255  # off the DEM: neither truth nor map there
    t = score_gully_areas(truth, {"a": (gully, grid)}).set_index("map_variant")
    assert t.loc["a", "truth_area_m2"] == 35.0 and t.loc["a", "predicted_area_m2"] == 40.0
    assert t.loc["a", "precision"] == pytest.approx(20 / 40) and t.loc["a", "recall"] == pytest.approx(20 / 35)


def test_score_networks_side_by_side_equal_each_scored_alone():
    ref, ext = _networks()
    params = ValidationParams(tolerance_m=5.0, extra_tolerances_m=(2.0,), reference_join_m=3.0)
    digitised = ext.iloc[:1].copy()  # the same network without the spur
    res, alone = score_networks(ref, ext, digitised, _valid(), GRID, params)
    solo = score_network(ref, ext, _valid(), GRID, params)
    solo_digitised = score_network(ref, digitised, _valid(), GRID, params, geometries=False)
    assert res.table.equals(solo.table) and res.tolerances.equals(solo.tolerances)
    assert alone.table.equals(solo_digitised.table) and alone.tolerances.equals(solo_digitised.tolerances)
    assert set(res.pieces) == {"good_fit", "false_negative", "false_positive", "not_scored"} and not alone.pieces
    assert alone.percent()["false_positive"] == pytest.approx(0.0) and res.percent()["false_positive"] > 0
    only, none = score_networks(ref, ext, None, _valid(), GRID, params)
    assert none is None and only.table.equals(solo.table)
