"""Tests of the digital twin (issue 3) on the tiny_twin tile, generated once per module."""

from __future__ import annotations

import copy
import hashlib
from pathlib import Path

import geopandas as gpd
import numpy as np
import pandas as pd
import pytest
import rasterio
import shapely

from kitegully import InputError
from kitegully.config import load_yaml
from kitegully.io.raster import read_raster
from kitegully.twin.landcover import CODE, VEGETATION
from kitegully.twin.site import OBSERVED_FILES, TRUTH_FILES, TwinParams, build_site, generate_epoch, sub_seed
from kitegully.twin.survey import rtk_observe
from kitegully.twin.targets import eligible, sample_bilinear
from kitegully.twin.terrain import pregully_grid

from conftest import REPO
SITE = load_yaml(REPO / "config" / "sites" / "tiny_twin.yaml")
TW = SITE["twin"]
PARAMS = TwinParams.from_config(TW)
CRS = SITE["site"]["crs"]
SEED = SITE["seed"]


@pytest.fixture(scope="module")
def twin(tmp_path_factory):
    root = tmp_path_factory.mktemp("twin")
    s1 = build_site(PARAMS, CRS, SEED, epoch=1)
    generate_epoch(s1, root / "a")
    fixed = {"targets": pd.read_csv(root / "a/truth/targets.csv"), "checkpoints": pd.read_csv(root / "a/truth/checkpoints.csv")}
    s2 = build_site(PARAMS, CRS, SEED, epoch=2)
    generate_epoch(s2, root / "a/epoch2", fixed_points=fixed)
    return {"root": root, "site": s1, "site2": s2}


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_all_contract_files_written(twin):
    d = twin["root"] / "a"
    for sub in (d, d / "epoch2"):
        for n in TRUTH_FILES:
            assert (sub / "truth" / n).is_file(), n
        for n in OBSERVED_FILES:
            assert (sub / "observed" / n).is_file(), n


def test_same_seed_identical_files(twin):
    """A second generation with the same config gives identical rasters, tables and vectors."""
    root = twin["root"]
    generate_epoch(build_site(PARAMS, CRS, SEED, epoch=1), root / "b")
    for n in ["dtm.tif", "dsm.tif", "landcover.tif", "texture.tif"]:
        a, _ = read_raster(root / "a/truth" / n, band=None)
        b, _ = read_raster(root / "b/truth" / n, band=None)
        np.testing.assert_array_equal(a, b)
    for sub, n in [("truth", "targets.csv"), ("truth", "checkpoints.csv"), ("observed", "gcp_survey.csv"), ("observed", "checkpoints.csv")]:
        assert _digest(root / "a" / sub / n) == _digest(root / "b" / sub / n), n
    for sub, n in [("truth", "gully_centrelines.gpkg"), ("truth", "gully_polygons.gpkg"), ("observed", "field_network.gpkg")]:
        ga, gb = gpd.read_file(root / "a" / sub / n), gpd.read_file(root / "b" / sub / n)
        assert len(ga) == len(gb) and ga.geometry.geom_equals_exact(gb.geometry, 0.0).all(), n


def test_different_seed_differs():
    a = build_site(PARAMS, CRS, SEED, epoch=1)
    b = build_site(PARAMS, CRS, SEED + 1, epoch=1)
    assert len(a.network) != len(b.network) or not np.allclose(a.network[1].x[:5], b.network[1].x[:5])


def test_crs_and_geotransform(twin):
    d = twin["root"] / "a/truth"
    e = TW["extent"]
    cell = TW["dem_cell_m"]
    for n in ["dtm.tif", "dsm.tif", "landcover.tif"]:
        with rasterio.open(d / n) as src:
            assert src.crs.to_string() == CRS
            t = src.transform
            assert (t.a, t.b, t.d, t.e) == (cell, 0.0, 0.0, -cell)
            assert t.c == pytest.approx(e["xmin"]) and t.f == pytest.approx(e["ymin"] + e["height_m"])
            assert (src.width, src.height) == (round(e["width_m"] / cell), round(e["height_m"] / cell))
    with rasterio.open(d / "dtm.tif") as src:
        assert src.dtypes[0] == "float32" and np.isnan(src.nodata)
    with rasterio.open(d / "texture.tif") as src:
        assert src.count == 4 and src.dtypes[0] == "uint8"
        assert src.transform.a == pytest.approx(TW["texture_cell_m"]) and src.crs.to_string() == CRS
        assert src.bounds.left == pytest.approx(e["xmin"]) and src.bounds.top == pytest.approx(e["ymin"] + e["height_m"])
        assert [s.lower() for s in src.descriptions] == ["red", "green", "blue", "nir"]


def test_terrain_physical_ranges(twin):
    dtm, grid = read_raster(twin["root"] / "a/truth/dtm.tif")
    dsm, _ = read_raster(twin["root"] / "a/truth/dsm.tif")
    lc, _ = read_raster(twin["root"] / "a/truth/landcover.tif")
    assert np.isfinite(dtm).all()
    # DSM never below the DTM; objects (shrubs, trees, buildings) make it higher
    assert (dsm >= dtm - 1e-4).all()
    veg = np.isin(lc, [CODE["shrub"], CODE["tree"]])
    assert (dsm[veg] - dtm[veg]).mean() > 0.2
    bare = np.isin(lc, [CODE["bare_eroded"], CODE["ploughed"], CODE["track"], CODE["gully"]])
    np.testing.assert_array_equal(dsm[bare], dtm[bare])
    # slopes locally above 45 degrees (gully walls), nothing perfectly flat
    gy, gx = np.gradient(dtm.astype(float), grid.cell)
    slope = np.degrees(np.arctan(np.hypot(gx, gy)))
    assert (slope > 45).sum() > 100
    assert (slope[lc != CODE["water"]] < 0.01).mean() < 0.01


def test_centreline_vertices_below_surrounding_terrain(twin):
    """Every vertex lies below the terrain 10 m either side by its depth minus a tolerance.

    The stated tolerance has two parts, both derived from how the terrain is built:

    * bed sampling: a V (or U of exponent p) of half-width h narrower than a cell cannot be
      resolved by the DEM, so the cell minimum misses up to D·min(1, (cell/√2 / h)^p);
    * pre-gully relief across the channel: where the surface the gully was cut into
      (valley + all micro-relief octaves, rebuilt here from the same seed) falls from the
      centreline to a side point, that side is lower by exactly that amount before any
      carving: max(0, z_pre(centre) − z_pre(side)).

    Field humps and furrow ridges only add height on the sides, so no term is needed for
    them. Side points inside another gully (polygon + 0.5 m) are skipped.
    """
    site = twin["site"]
    dtm, grid = read_raster(twin["root"] / "a/truth/dtm.tif")
    polys = gpd.read_file(twin["root"] / "a/truth/gully_polygons.gpkg").buffer(0.5).union_all()
    xs, ys = grid.cell_centres()
    pre = pregully_grid(site.valley, xs, ys, sub_seed(SEED, "relief"), site.wl, site.amp)
    margins = []
    for g in site.network:
        x, y, D, h = g.x, g.y, g.depth, 0.5 * g.width
        tx, ty = np.gradient(x), np.gradient(y)
        nn = np.hypot(tx, ty)
        nx, ny = -ty / nn, tx / nn
        r, c = grid.rowcol(x, y)
        ri, ci = np.round(r).astype(int), np.round(c).astype(int)
        ok = (D >= TW["gullies"]["min_depth_m"]) & (ri >= 1) & (ri < grid.height - 1) & (ci >= 1) & (ci < grid.width - 1)
        for i in np.nonzero(ok)[0]:
            zc = dtm[ri[i] - 1:ri[i] + 2, ci[i] - 1:ci[i] + 2].min()
            px = x[i] + np.array([1.0, -1.0]) * 10.0 * nx[i]
            py = y[i] + np.array([1.0, -1.0]) * 10.0 * ny[i]
            inside = shapely.contains_xy(polys, px, py)
            zs = sample_bilinear(dtm, grid, px, py)
            zs_pre = sample_bilinear(pre, grid, px, py)
            zc_pre = sample_bilinear(pre, grid, x[i:i + 1], y[i:i + 1])[0]
            p = TW["gullies"]["u_shape_exponent"] if g.shape == "U" else 1.0
            tol_bed = D[i] * min(1.0, (grid.cell / np.sqrt(2) / h[i]) ** p)
            for j in range(2):
                if inside[j] or not np.isfinite(zs[j]):
                    continue
                tol = tol_bed + max(0.0, zc_pre - zs_pre[j])
                margins.append(zs[j] - zc - (D[i] - tol))
    margins = np.array(margins)
    assert len(margins) > 400
    assert margins.min() >= -1e-3, f"{(margins < -1e-3).sum()} of {len(margins)} sides, worst {margins.min():.3f} m"


def test_tributaries_end_on_the_receiving_channel(twin):
    """A gully that joins another ends on that channel's centreline (a shared confluence
    node, within one trace step), unless it runs into the reservoir, where it ends at the water."""
    site = twin["site"]
    by_id = {g.gully_id: g for g in site.network}
    step = TW["gullies"]["trace_step_m"]
    joined = [g for g in site.network if g.joins >= 0 and g.kind != "wadi"]
    assert joined
    n_on = 0
    for g in joined:
        tgt = by_id[g.joins]
        gap = np.hypot(tgt.x - g.x[-1], tgt.y - g.y[-1]).min()
        u, _ = site.valley.uv(g.x[-1], g.y[-1])
        in_lake = bool(site.valley.lake_zone(np.array([u]))[0])
        assert gap <= step or (g.joins == 0 and in_lake), f"gully {g.gully_id} ends {gap:.1f} m from gully {g.joins}"
        n_on += gap <= step
    assert n_on >= 1


def test_truth_centrelines_attributes(twin):
    cl = gpd.read_file(twin["root"] / "a/truth/gully_centrelines.gpkg")
    assert {"gully_id", "width_m", "depth_m"} <= set(cl.columns)
    assert cl.crs.to_string() == CRS
    g = cl[cl["kind"] != "wadi"]
    assert g["depth_min_m"].min() >= TW["gullies"]["min_depth_m"] - 1e-9
    assert cl["width_m"].max() <= TW["gullies"]["wadi"]["width_outlet_m"] + 1e-6
    assert g["gully_id"].nunique() >= 3
    heads = gpd.read_file(twin["root"] / "a/truth/gully_heads.gpkg")
    assert len(heads) == len(twin["site"].network) - 1


def test_observed_holds_no_truth(twin):
    for sub in (twin["root"] / "a", twin["root"] / "a/epoch2"):
        obs = sub / "observed"
        names = {p.name for p in obs.iterdir()}
        assert names <= set(OBSERVED_FILES) | {"checkpoints.md", "gcp_survey.md"}
        assert not any(n.endswith(".tif") for n in names)
        truth_digests = {_digest(p) for p in (sub / "truth").iterdir()}
        assert not any(_digest(p) in truth_digests for p in obs.iterdir())
        t = pd.read_csv(sub / "truth/checkpoints.csv")
        o = pd.read_csv(obs / "checkpoints.csv")
        assert list(o.columns) == ["id", "x", "y", "z"]
        assert (t[["x", "y", "z"]].to_numpy() != o[["x", "y", "z"]].to_numpy()).all()
        g = pd.read_csv(obs / "gcp_survey.csv")
        assert list(g.columns) == ["gcp_id", "x", "y", "z"]
        fn = gpd.read_file(obs / "field_network.gpkg")
        assert not {"depth_m", "depth_min_m", "kind", "shape"} & set(fn.columns)
    # the site.json a planner gets has no truth either
    from kitegully.twin.site import site_json
    js = site_json(twin["site"])
    assert set(js) == {"name_hint", "crs", "extent", "dem_cell_m", "texture_cell_m", "approx_elevation_m", "epochs"}


def test_field_network_leaves_out_reaches_under_the_reservoir(twin):
    """Surveyors walk and map gullies on land: no surveyed vertex lies on a water cell
    (checked without the mapping displacement), while the truth wadi does run under water."""
    from kitegully.twin import survey

    lc, grid = read_raster(twin["root"] / "a/truth/landcover.tif")
    water = lc == CODE["water"]
    wadi = twin["site"].network[0]
    assert survey._under_water(wadi.x, wadi.y, water, grid).any()
    sv = dict(TW["survey"]["field_network"], mapping_error_m=0.0)
    fn = survey.field_network(twin["site"].network, sv, TW["gullies"]["min_depth_m"], CRS, 7, water=water, grid=grid)
    xy = np.concatenate([np.asarray(g.coords) for g in fn.geometry])
    assert not survey._under_water(xy[:, 0], xy[:, 1], water, grid).any()
    dry = survey.field_network(twin["site"].network, sv, TW["gullies"]["min_depth_m"], CRS, 7)
    assert dry.length.sum() > fn.length.sum() + 10 * TW["dem_cell_m"]


def test_checkpoint_noise_matches_sigma(twin):
    t = pd.read_csv(twin["root"] / "a/truth/checkpoints.csv")
    o = pd.read_csv(twin["root"] / "a/observed/checkpoints.csv")
    s = TW["survey"]
    dh = np.concatenate([(o.x - t.x).to_numpy(), (o.y - t.y).to_numpy()])
    dz = (o.z - t.z).to_numpy()
    for d, sigma in ((dh, s["rtk_sigma_h_m"]), (dz, s["rtk_sigma_v_m"])):
        n = len(d)
        # standard error of a sample SD is σ/√(2n); of a mean σ/√n; allow 4 standard errors
        assert abs(d.std(ddof=1) - sigma) < 4 * sigma / np.sqrt(2 * n)
        assert abs(d.mean()) < 4 * sigma / np.sqrt(n)


def test_rtk_noise_large_sample():
    rng = np.random.default_rng(0)
    n = 20000
    df = pd.DataFrame({"id": np.arange(n), "x": np.zeros(n), "y": np.zeros(n), "z": np.zeros(n)})
    o = rtk_observe(df, "id", 0.015, 0.03, rng)
    assert o.x.std() == pytest.approx(0.015, rel=4 / np.sqrt(2 * n))
    assert o.z.std() == pytest.approx(0.03, rel=4 / np.sqrt(2 * n))


def test_checkpoints_avoid_vegetation(twin):
    lc, grid = read_raster(twin["root"] / "a/truth/landcover.tif")
    t = pd.read_csv(twin["root"] / "a/truth/checkpoints.csv")
    c = TW["survey"]["checkpoints"]
    assert len(t) == c["count"]
    assert eligible(lc, grid, t.x.to_numpy(), t.y.to_numpy(), c["open_classes"], c["clearance_m"]).all()
    veg = [CODE[v] for v in VEGETATION]
    r, cc = grid.rowcol(t.x.to_numpy(), t.y.to_numpy())
    assert not np.isin(lc[np.round(r).astype(int), np.round(cc).astype(int)], veg).any()


def test_gcp_targets_painted_and_on_dsm(twin):
    d = twin["root"] / "a/truth"
    tg = pd.read_csv(d / "targets.csv")
    assert len(tg) >= 8
    dsm, grid = read_raster(d / "dsm.tif")
    np.testing.assert_allclose(tg.z, sample_bilinear(dsm, grid, tg.x, tg.y), atol=1e-4)
    tex, tgrid = read_raster(d / "texture.tif", band=None)
    q = 0.25 * TW["targets"]["size_m"]
    for t in tg.itertuples():
        vals = []
        for sx, sy in ((1, 1), (-1, 1), (-1, -1), (1, -1)):
            r, c = tgrid.rowcol(t.x + sx * q, t.y + sy * q)
            vals.append(int(tex[0, int(round(float(r))), int(round(float(c)))]))
        # checker: NE and SW dark, NW and SE white
        assert vals[0] < 30 and vals[2] < 30 and vals[1] > 200 and vals[3] > 200


def test_texture_excess_green_separates_grass(twin):
    d = twin["root"] / "a/truth"
    tex, tgrid = read_raster(d / "texture.tif", band=None)
    lc, grid = read_raster(d / "landcover.tif")
    k = TW["dem_cell_m"] / TW["texture_cell_m"]
    rgb = tex[:3, ::int(k), ::int(k)].astype(float)
    s = rgb.sum(axis=0) + 1e-6
    exg = 2 * rgb[1] / s - rgb[0] / s - rgb[2] / s
    grass = exg[lc == CODE["grass"]]
    soil = exg[np.isin(lc, [CODE["bare_eroded"], CODE["ploughed"]])]
    assert np.median(grass) > np.percentile(soil, 95)
    # high-frequency texture everywhere but on water: neighbouring texels differ
    diff = np.abs(np.diff(tex[1].astype(int), axis=1))
    assert (diff > 0).mean() > 0.5


def test_epoch2_only_erodes(twin):
    a, _ = read_raster(twin["root"] / "a/truth/dtm.tif")
    b, _ = read_raster(twin["root"] / "a/epoch2/truth/dtm.tif")
    lc, _ = read_raster(twin["root"] / "a/truth/landcover.tif")
    assert (b <= a + 1e-4).all()
    bare = lc == CODE["bare_eroded"]
    e = TW["epoch2"]
    # sheet erosion: mean lowering equals the configured mean within its variability / √(patches)
    assert np.mean(a[bare] - b[bare]) == pytest.approx(e["sheet_erosion_m"], rel=0.35)
    h1 = gpd.read_file(twin["root"] / "a/truth/gully_heads.gpkg")
    h2 = gpd.read_file(twin["root"] / "a/epoch2/truth/gully_heads.gpkg")
    moved = h2["retreat_m"] > 0
    assert moved.any()
    d = h1.geometry.distance(h2.geometry)
    np.testing.assert_allclose(d[moved], h2["retreat_m"][moved], atol=1e-6)
    p1 = gpd.read_file(twin["root"] / "a/truth/gully_polygons.gpkg").area.sum()
    p2 = gpd.read_file(twin["root"] / "a/epoch2/truth/gully_polygons.gpkg").area.sum()
    assert p2 > p1 * (1 + e["widening_fraction"][0] * 0.5)


def test_bad_texture_cell_is_input_error():
    bad = copy.deepcopy(TW)
    bad["texture_cell_m"] = 0.15
    with pytest.raises(InputError, match="texture_cell_m"):
        TwinParams.from_config(bad)


def test_params_take_the_keys_a_rule_passes():
    from kitegully.twin import EPOCH_KEYS, PLAN_KEYS

    plan = TwinParams.from_config({k: TW[k] for k in PLAN_KEYS})
    assert plan.survey is None and plan.epoch2 is None and plan.tex_factor == round(TW["dem_cell_m"] / TW["texture_cell_m"])
    with pytest.raises(InputError, match=r"twin.epoch2: needed to plan epoch 2"):
        build_site(plan, CRS, SEED, epoch=2)
    with pytest.raises(InputError, match=r"twin: missing key 'survey' \(the epoch keys"):
        TwinParams.from_config({k: TW[k] for k in PLAN_KEYS + EPOCH_KEYS if k != "survey"})
    with pytest.raises(InputError, match=r"twin: unknown key 'dem_cell'"):
        TwinParams.from_config({**TW, "dem_cell": 1.0})
    with pytest.raises(TypeError):
        PARAMS.gullies["min_depth_m"] = 0.0  # read-only


def test_site_config_files_validate():
    from kitegully.config import validate_config

    for s in ("kamech_twin.yaml", "tiny_twin.yaml"):
        cfg = load_yaml(REPO / "config/config.yaml")
        cfg.update(load_yaml(REPO / "config/sites" / s))
        validate_config(cfg, sources=[REPO / "config/sites" / s])
    bad = load_yaml(REPO / "config/sites/tiny_twin.yaml")
    bad["twin"]["gullies"]["u_shape_share"] = 2.0
    cfg = load_yaml(REPO / "config/config.yaml")
    cfg.update(bad)
    with pytest.raises(InputError, match="twin.gullies.u_shape_share"):
        validate_config(cfg)
