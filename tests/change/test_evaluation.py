"""Moritani's MAE/MRE/b and the detection table on constructed cases."""

import numpy as np
import pytest

from kitegully.change.evaluation import detection_table, moritani_plots


def test_moritani_perfect_and_scaled():
    true = np.zeros((40, 40), np.float32)
    true[:20, :20] = -0.1
    true[20:, 20:] = -0.05
    df, s = moritani_plots(true, true, 1.0, 10.0, 0.02)
    assert s["plots"] == 8 and s["mae_m"] == 0 and s["b"] == pytest.approx(1.0)
    df, s = moritani_plots(1.2 * true, true, 1.0, 10.0, 0.02)
    assert s["b"] == pytest.approx(1.2, rel=1e-5) and s["mre_pct"] == pytest.approx(20.0, rel=1e-5)


def test_detection_counts():
    true = np.array([0.5, -0.5, 0.5, 0.0, 0.0, 0.0], np.float32)
    dod = np.array([0.4, -0.4, -0.3, 0.2, 0.0, 0.01], np.float32)
    sigma = np.full(6, 0.1, np.float32)
    det = {"probabilistic": np.array([True, True, True, True, False, False])}
    row = detection_table(dod, sigma, true, det).iloc[0]
    assert (row.true_change_cells, row.detected, row.missed) == (3, 2, 1)  # wrong sign counts as missed
    assert (row.stable_cells, row.false) == (3, 1)


def test_headcut_ceiling_measures_the_true_surfaces(tmp_path):
    """The method run on two constructed 'true' surfaces (a headwall retreated 1.5 m): its table and rows."""
    import geopandas as gpd
    import pandas as pd
    from shapely.geometry import Point

    from change.test_headcuts import HEADS, PARAMS, _pair
    from change.change_synth import CRS, grid
    from kitegully.change.evaluation import _headcut_ceiling
    from kitegully.io.raster import Raster

    g = grid(200, cell=0.2)
    z1, z2 = _pair(g, 1.5, 1, sd=0.0)
    crs = CRS
    heads = tmp_path / "heads.gpkg"
    gpd.GeoDataFrame(dict(head_id=HEADS.head_id), geometry=[Point(x, y) for x, y in zip(HEADS.x, HEADS.y)],
                     crs=crs).to_file(heads)
    true = {}
    for k, x in (("1", g.x0 + 20.0), ("2", g.x0 + 18.5)):
        true[k] = tmp_path / f"true_heads{k}.gpkg"
        gpd.GeoDataFrame(dict(gully_id=[5], retreat_m=[1.5]), geometry=[Point(x, g.y0 - 20.0)], crs=crs).to_file(true[k])
    rows = _headcut_ceiling(Raster(z1, g), Raster(z2, g), g, (str(heads), PARAMS), str(true["1"]), str(true["2"]),
                            {"head_match_m": 10.0}, str(tmp_path / "ceiling.csv"))
    table = pd.read_csv(tmp_path / "ceiling.csv")
    assert table["retreat_m"].iloc[0] == pytest.approx(1.5, abs=0.2)
    assert table["true_retreat_m"].iloc[0] == pytest.approx(1.5)
    values = {q: v for q, v, _ in rows}
    assert values["headcut |error| n, heads that retreated, lip, method on the true surfaces"] == 1
    assert values["headcut |error| median, heads that retreated, lip, method on the true surfaces"] < 0.2
