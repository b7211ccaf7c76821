"""The change stage as tile jobs (kitegully.change.tiles, issue 21): tiled equals untiled.

A synthetic pair on an uneven 160 x 140-cell grid (3 x 3 tiles of 53-54 x 46-47 cells):
epoch 2 is shifted (0.4, -0.3) m, raised 0.1 m and tilted, with a pit and a mound; epoch 1
has a nodata hole, both epochs a correlation raster with low-NCC patches (voids with a
margin), a shrub (an above-ground object), a gully mask by id (unstable), a land-cover class
raster (budget rows only), a digitised head and a cross-section. Epoch 1's σ comes from
checkpoints, epoch 2's from an error raster. The sample of the co-registration is strided
(``coreg_max_samples`` below the candidate cells).
"""

from __future__ import annotations

import json

import geopandas as gpd

import numpy as np
import pandas as pd
import rasterio
from shapely.geometry import LineString, Point, box

from change.change_synth import CRS, bump, noise, terrain, write, xy
from kitegully.change.params import THRESHOLD_METHODS, ChangeParams
from kitegully.change.params import OUTPUTS
from kitegully.change.stage import detect_change
from kitegully.change.tiles import change_tile, coregister_tiles, halos, merge_change, plan_change, stable_tile
from kitegully.io.raster import GridSpec, Raster
from kitegully.terrain.tiling import TilingParams

PARAMS = ChangeParams(variogram_max_lag_m=30.0, variogram_samples=1500, coreg_max_samples=3000, void_margin_m=0.5,
                      min_correlation=0.5, seed=3)


def _site(d):
    g = GridSpec(500000.0, 4100000.0, 0.5, 140, 160, CRS)
    X, Y = xy(g)
    z = terrain(X, Y)
    shrub = 1.2 * (np.hypot(X - (g.x0 + 50), Y - (g.y0 - 20)) < 1.0)
    change = bump(g, 30.0, 30.0, 8.0, -0.8) + bump(g, 52.0, 60.0, 6.0, 0.5)
    dx, dy = 0.4, -0.3
    z2 = terrain(X - dx, Y - dy) + change + 0.1 + 0.002 * (X - g.x0) + shrub
    z1 = z + shrub + noise(g, 0.03, "t1")
    z1[100:108, 20:35] = np.nan
    z2 = z2 + noise(g, 0.03, "t2")
    c1 = np.full(z1.shape, 0.9)
    c1[40:44, 60:90] = 0.2  # a low-NCC strip across a seam
    c2 = np.full(z1.shape, 0.9)
    c2[10:30, 100:103] = 0.3
    files = dict(dem1=write(d / "dem1.tif", z1, g), dem2=write(d / "dem2.tif", z2, g),
                 c1=write(d / "c1.tif", c1, g), c2=write(d / "c2.tif", c2, g),
                 err2=write(d / "err2.tif", 0.03 + 0.01 * (X - g.x0) / 70.0, g))
    rng = np.random.default_rng(2)
    r, c = rng.integers(5, 155, 150), rng.integers(5, 135, 150)
    pd.DataFrame(dict(id=range(150), x=X[r, c], y=Y[r, c], z=z[r, c])).to_csv(d / "cp1.csv", index=False)
    gpd.GeoDataFrame({"gully_id": [2, 1]}, geometry=[box(g.x0 + 20, g.y0 - 40, g.x0 + 40, g.y0 - 20),
                                                     box(g.x0 + 45, g.y0 - 68, g.x0 + 60, g.y0 - 52)], crs=CRS).to_file(d / "gully.gpkg")
    lc = np.where(X - g.x0 < 23.3, 3, np.where(Y > g.y0 - 47.1, 5, 1)).astype(np.uint8)  # seams cut every class
    Raster(lc, g, 0).write(d / "lc.tif")
    pd.DataFrame({"code": [1, 3, 5], "name": ["bare", "grass", "shrub"]}).to_csv(d / "lc.csv", index=False)
    gpd.GeoDataFrame({"head_id": [1]}, geometry=[Point(g.x0 + 30, g.y0 - 30)], crs=CRS).to_file(d / "heads.gpkg")
    gpd.GeoDataFrame({"polygon_id": [1], "station_m": [5.0], "width_m": [10.0]},
                     geometry=[LineString([(g.x0 + 22, g.y0 - 30), (g.x0 + 38, g.y0 - 30)])], crs=CRS).to_file(d / "sec.gpkg")
    epochs = [dict(name="e1", dem=files["dem1"], nodata=None, correlation=files["c1"], accuracy=dict(checkpoints=str(d / "cp1.csv"))),
              dict(name="e2", dem=files["dem2"], nodata=None, correlation=files["c2"], accuracy=dict(error_raster=files["err2"]))]
    masks = [dict(name="gully", file=str(d / "gully.gpkg"), kind="vector", by="gully_id", unstable=True),
             dict(name="landcover", file=str(d / "lc.tif"), kind="raster", classes=str(d / "lc.csv"), values=None, unstable=False)]
    return epochs, masks, str(d / "heads.gpkg"), str(d / "sec.gpkg")


def _outs(d):
    names = {k: f"{k}.{'tif' if k in ('dod', 'sigma_dod', 'stable') else 'png' if k in ('dod_map', 'budget_bars', 'histogram', 'variogram_png') else 'csv'}"
             for k in OUTPUTS}
    names.update({f"thresholded_{m}": f"thr_{m}.tif" for m in THRESHOLD_METHODS})
    d.mkdir()
    return {k: str(d / v) for k, v in names.items()}


def _run_tiles(tmp_path, epochs, masks, heads, secs, params, tiling):
    """The five tile rules in order (stable tiles and change tiles merged in reverse order); (outputs, summary, work dir)."""
    w = tmp_path / "tiles"
    w.mkdir()
    plan_change(epochs, w / "plan.json", CRS)
    st = [w / f"{n}.stable.npz" for n in tiling.names()]
    for n, f in zip(tiling.names(), st):
        stable_tile(epochs, masks, w / "plan.json", params, tiling, n, f, CRS)
    coregister_tiles(st[::-1], epochs, params, w / "coreg.json", CRS)
    ct = [w / f"{n}.change.npz" for n in tiling.names()]
    for n, s, f in zip(tiling.names(), st, ct):
        change_tile(epochs, masks, w / "plan.json", w / "coreg.json", s, params, tiling, n, f, CRS)
    out = _outs(tmp_path / "tiled")
    summary = merge_change(ct[::-1], w / "plan.json", w / "coreg.json", epochs, heads, params, out, site_crs=CRS,
                           sections_path=secs)
    return out, summary, w


def test_tiled_change_equals_untiled(tmp_path):
    epochs, masks, heads, secs = _site(tmp_path)
    ref = _outs(tmp_path / "untiled")
    s_ref = detect_change(epochs, masks, heads, PARAMS, ref, site_crs=CRS, sections_path=secs)
    tiling = TilingParams(30.0, 70.0, 80.0)  # 3 x 3 tiles
    assert halos(PARAMS, 0.5) == (11, 5)
    out, s, w = _run_tiles(tmp_path, epochs, masks, heads, secs, PARAMS, tiling)
    assert s["tiles"] == 9
    # every raster bit for bit (DoD with voids, sigma from the error raster, stable ground, the
    # four thresholds incl. the 5 x 5 coherence across the seams)
    for k in ("dod", "sigma_dod", "stable", *(f"thresholded_{m}" for m in THRESHOLD_METHODS)):
        with rasterio.open(ref[k]) as a, rasterio.open(out[k]) as b:
            x, y = a.read(1), b.read(1)
            assert a.transform == b.transform and a.tags() == b.tags()
        assert np.array_equal(x, y, equal_nan=True), k
    dod = Raster.read(ref["dod"]).data
    assert np.isnan(dod).sum() > 150  # the hole and the voids are in it
    # the global co-registration, the stats, variogram, thresholds, headcuts and widening: identical
    for k in ("coregistration", "sigma", "thresholds", "variogram", "headcuts", "widening"):
        a, b = pd.read_csv(ref[k]), pd.read_csv(out[k])
        pd.testing.assert_frame_equal(a, b, check_exact=True, obj=k)
    co = pd.read_csv(ref["coregistration"]).set_index("quantity")["value"]
    assert abs(co["dx"] - 0.4) < 0.05 and abs(co["dy"] + 0.3) < 0.05 and co["converged"] == 1
    # budgets from per-tile partial sums: the same rows in the same order, values to rounding
    a, b = pd.read_csv(ref["budget"]), pd.read_csv(out["budget"])
    assert list(a["mask"]) == list(b["mask"]) and list(a["method"]) == list(b["method"])
    assert {"gully:1", "gully:2", "landcover:bare", "landcover:grass", "landcover:shrub"} <= set(a["mask"])
    num = a.columns[2:]
    np.testing.assert_allclose(b[num].to_numpy(float), a[num].to_numpy(float), rtol=1e-12, atol=1e-12)
    assert s["net_m3"] == s_ref["net_m3"] or abs(s["net_m3"] - s_ref["net_m3"]) < 1e-9


def test_tiled_change_with_the_terrain_dependent_sigma_equals_untiled(tmp_path, monkeypatch):
    """The error model is fitted once on the same lattice cells from the tiles and applied per tile: sigma bit for bit."""
    import dataclasses

    from kitegully.change import error_model as em

    monkeypatch.setattr(em, "BINS", 3)  # a small grid: 27 bins of >= 20 cells
    monkeypatch.setattr(em, "MIN_CELLS", 20)
    monkeypatch.setattr(em, "MAX_SAMPLES", 6000)  # every 2nd row and column
    epochs, masks, heads, secs = _site(tmp_path)
    epochs[1]["accuracy"] = {"sd_m": 0.04}  # checkpoints on epoch 1 only: the reference is theirs
    het = dataclasses.replace(PARAMS, heteroscedastic=True)
    assert em.lattice_step(140 * 160) == 2
    ref = _outs(tmp_path / "untiled")
    detect_change(epochs, masks, heads, het, ref, site_crs=CRS, sections_path=secs)
    sig = pd.read_csv(ref["sigma"]).set_index("epoch")
    assert "median" in sig.loc["DoD factor", "source"]
    tiling = TilingParams(30.0, 70.0, 80.0)
    a, b = halos(het, 0.5)
    assert b >= em.predictor_halo(0.5, het.headcut_window_m, het.stable_object_window_m)
    out, _, w = _run_tiles(tmp_path, epochs, masks, heads, secs, het, tiling)
    assert json.loads((w / "coreg.json").read_text())["error_model"] is not None
    for k in ("dod", "sigma_dod", *(f"thresholded_{m}" for m in THRESHOLD_METHODS)):
        with rasterio.open(ref[k]) as x, rasterio.open(out[k]) as y:
            assert x.tags() == y.tags()
            assert np.array_equal(x.read(1), y.read(1), equal_nan=True), k
    with rasterio.open(ref["sigma_dod"]) as x:
        s_ = x.read(1)
        assert "heteroscedastic" in x.tags()["definition"] and np.nanmax(s_) > np.nanmin(s_)
    pd.testing.assert_frame_equal(pd.read_csv(ref["sigma"]), pd.read_csv(out["sigma"]), check_exact=False, rtol=1e-9)
