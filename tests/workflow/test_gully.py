"""Gully rules on the tiny_twin site (``gully.dem: dense``: the photogrammetric DSM).

The fast tests fabricate the few upstream files the gully stage reads from an analytic
catchment: the dense DSM (``dense/dsm.tif``, with what dense matching puts in a surface:
correlated matching noise, shrubs and crop above the ground, small unmatched gaps), the
observed heads and field network, and the truth polygons; ``--allowed-rules`` keeps
Snakemake from running the twin, flight, SfM and dense rules. The truth-plus-noise DEM is
exercised only as the labelled evaluation stand-in. The slow test runs the real chain
(twin -> flight -> SfM -> georeferencing -> dense matching -> gully) on the tiny twin.
"""

from __future__ import annotations

from pathlib import Path

import geopandas as gpd
import numpy as np
import pandas as pd
import pytest
import scipy.ndimage as ndi
import shapely
import yaml

from kitegully.io.raster import GridSpec, read_raster, write_raster
from kitegully.io.vectors import read_vector, write_vector
from kitegully.logs import read_peak_memory
from snakemake_utils import REPO, run_snakemake
from .tiny_sfm import copy_results

SITE = REPO / "config" / "sites" / "tiny_twin.yaml"
CRS = "EPSG:32632"
GULLY_RULES = ["gully_standin_dem", "gully_map", "gully_section", "gully_validate", "gully_area_scores", "gully_sensitivity"]


def fabricate_twin(twin: Path) -> dict:
    """A 120 m x 160 m slope with a Y-shaped V gully system (depth 1.2 m, width 6 m)."""
    cell = 0.2
    grid = GridSpec(600000.0, 4100000.0, cell, 600, 800, CRS)
    xs, ys = grid.cell_centres()
    x = xs[None, :] - xs[0]
    y = ys[:, None] - ys[-1]
    z = 50 + 0.04 * y + 0.01 * x + 0.3 * np.sin(x / 17.0) * np.cos(y / 23.0)
    trunk = shapely.LineString([(60, 0), (60, 70)])
    left = shapely.LineString([(60, 70), (30, 130)])
    right = shapely.LineString([(60, 70), (95, 140)])
    lines_local = [trunk, left, right]
    pts = shapely.points(np.column_stack([np.broadcast_to(x, z.shape).ravel(), np.broadcast_to(y, z.shape).ravel()]))
    dist = shapely.distance(shapely.union_all(lines_local), pts).reshape(z.shape)
    half_width, depth = 3.0, 1.2
    z = z - depth * np.clip(1 - dist / half_width, 0, None)
    z[:40, :60] = np.nan  # a corner outside the survey
    write_raster(twin / "truth" / "dtm.tif", z.astype(np.float32), grid)
    write_raster(twin.parent / "dense" / "dsm.tif", photogrammetric_dsm(z, x, y, dist, cell), grid)

    def to_map(g):
        return shapely.affinity.translate(g, xs[0], ys[-1])

    lines = [to_map(g) for g in lines_local]
    write_vector(
        gpd.GeoDataFrame({"gully_id": [1, 2, 3], "width_m": 6.0, "depth_m": depth}, geometry=lines, crs=CRS),
        twin / "truth" / "gully_centrelines.gpkg",
    )
    write_vector(
        gpd.GeoDataFrame({"gully_id": [1]}, geometry=[shapely.union_all([g.buffer(half_width) for g in lines])], crs=CRS),
        twin / "truth" / "gully_polygons.gpkg",
    )
    heads = [shapely.Point(l.coords[-1]) for l in lines[1:]]
    write_vector(gpd.GeoDataFrame({"head_id": [1, 2]}, geometry=heads, crs=CRS), twin / "observed" / "gully_heads.gpkg")
    # field network: GPS-walked lines, 0.5 m off the true centrelines
    field = [shapely.affinity.translate(l, 0.5, 0.0) for l in lines]
    write_vector(gpd.GeoDataFrame({"line_id": [1, 2, 3]}, geometry=field, crs=CRS), twin / "observed" / "field_network.gpkg")
    return {"grid": grid, "length": sum(l.length for l in lines)}


def photogrammetric_dsm(dtm: np.ndarray, x: np.ndarray, y: np.ndarray, dist: np.ndarray, cell: float) -> np.ndarray:
    """What dense matching makes of ``dtm``: a surface model with noise, vegetation and gaps.

    Correlated matching noise (SD 0.05 m over 0.5 m, the default twin's checkpoint SD),
    eight shrubs (1.5 m high, 1.5 m radius) and a 0.2 m crop over one field, all at least
    15 m from the gullies, and unmatched gaps (NaN, 1-2 m across) in the field and in a
    gully floor, which the mapping interpolates.
    """
    rng = np.random.default_rng(15)
    noise = ndi.gaussian_filter(rng.standard_normal(dtm.shape), 0.5 / cell)
    dsm = dtm + 0.05 * noise / noise.std()
    xx, yy = np.broadcast_to(x, dtm.shape), np.broadcast_to(y, dtm.shape)
    for sx, sy in [(15, 40), (20, 100), (100, 30), (105, 60), (110, 100), (15, 150), (80, 150), (40, 20)]:
        dsm += 1.5 * np.exp(-((xx - sx) ** 2 + (yy - sy) ** 2) / (2 * 1.5**2))
    dsm += np.where((xx > 80) & (yy < 50) & (dist > 15), 0.2, 0.0)
    for gx, gy in [(30, 60), (90, 120), (60, 30)]:  # (60, 30): in the trunk's floor
        dsm[(np.abs(xx - gx) < 1.0) & (np.abs(yy - gy) < 0.6)] = np.nan
    return dsm.astype(np.float32)


@pytest.fixture(scope="module")
def gully_run(tmp_path_factory):
    results = tmp_path_factory.mktemp("gully_results")
    info = fabricate_twin(results / "tiny_twin" / "twin")
    out = results / "tiny_twin" / "gully"
    targets = [str(out / n) for n in ("gully_summary.csv", "gully_section.png", "network_validation.csv",
                                       "gully_area_scores.csv", "gully_sensitivity.csv", "gully_validation_map.png")]
    run_snakemake(SITE, results, targets, extra=["--allowed-rules", *GULLY_RULES, "--printshellcmds"], cores=2)
    return results / "tiny_twin", info


def test_outputs_and_formats(gully_run):
    root, info = gully_run
    out = root / "gully"
    for name in ("depth.tif", "gully_map.tif", "gully_network.gpkg", "gully_polygons.gpkg", "gully_section.png",
                 "gully_validation_map.png", "network_validation.md", "gully_sensitivity.csv"):
        assert (out / name).exists(), name
    depth, grid = read_raster(out / "depth.tif")
    assert depth.dtype == np.float32 and grid == info["grid"]
    net = read_vector(out / "gully_network.gpkg", crs=CRS)
    assert {"stream_order", "length_m"} <= set(net.columns)
    assert net["stream_order"].max() == 2
    polys = read_vector(out / "gully_polygons.gpkg", crs=CRS)
    assert {"area_m2", "volume_m3", "mean_depth_m", "max_depth_m"} <= set(polys.columns)
    val = pd.read_csv(out / "network_validation.csv")
    assert list(val.columns) == ["category", "length_m", "percent"]
    assert list(val["category"]) == ["reference", "good_fit", "false_positive", "false_negative"]
    pct = dict(zip(val["category"], val["percent"]))
    assert pct["good_fit"] + pct["false_negative"] == pytest.approx(100)
    # reference clipped to the DEM footprint: at most the full line length
    assert val["length_m"].iloc[0] <= info["length"] + 1e-6
    sens = pd.read_csv(out / "gully_sensitivity.csv")
    assert len(sens) == 9 and {"iou", "good_fit_percent"} <= set(sens.columns)


def test_accuracy_on_analytic_twin(gully_run):
    # A clean 1.2 m deep V gully with 0.1 m noise: the network traced from the true heads
    # runs within a cell or two of the centreline (field lines are 0.5 m off), so with the
    # 5 m tolerance nearly all of the reference is found; what is lost is the end stretch
    # where the gully leaves the DEM (the last < 5 m) and cells under the depth threshold.
    root, _ = gully_run
    pct = dict(pd.read_csv(root / "gully" / "network_validation.csv").values[:, [0, 2]])
    assert pct["good_fit"] > 90
    assert pct["false_positive"] < 5
    area = pd.read_csv(root / "gully" / "gully_area_scores.csv").set_index("map_variant")
    # the mapped width is the width at depth > 0.25 m + smoothing loss, narrower than the 6 m truth
    assert area.loc["buffer_and_patches", "precision"] > 0.9
    assert 0.3 < area.loc["buffer_and_patches", "recall"] < 0.95


def test_maps_the_photogrammetric_dsm(gully_run):
    root, _ = gully_run
    summary = dict(pd.read_csv(root / "gully" / "gully_summary.csv").values)
    assert summary["DEM source"] == "dense"
    assert int(summary["interpolated hole cells"]) > 0  # the fabricated matching gaps
    assert not (root / "gully" / "standin_dem_truth_plus_noise.tif").exists()
    assert "NOT the photogrammetric DSM" not in (root / "logs" / "gully" / "map.log").read_text()
    assert read_peak_memory(root / "logs" / "gully" / "map.log") > 50  # the job's high-water mark ends its log


def test_standin_is_labelled_not_photogrammetric(tmp_path):
    """gully.dem: truth_plus_noise stays an evaluation stand-in, said so in its logs and tags."""
    info = fabricate_twin(tmp_path / "tiny_twin" / "twin")
    cfg = yaml.safe_load(SITE.read_text())
    cfg["gully"]["dem"] = "truth_plus_noise"
    site = tmp_path / "standin_site.yaml"
    site.write_text(yaml.safe_dump(cfg, sort_keys=False))
    out = tmp_path / "tiny_twin" / "gully"
    run_snakemake(site, tmp_path, [str(out / "gully_summary.csv")], extra=["--allowed-rules", *GULLY_RULES, "--nocolor"], cores=2)
    logs = tmp_path / "tiny_twin" / "logs" / "gully"
    assert "NOT the photogrammetric DSM" in (logs / "standin_dem.log").read_text()
    assert "NOT the photogrammetric DSM" in (logs / "map.log").read_text()
    summary = dict(pd.read_csv(out / "gully_summary.csv").values)
    assert summary["DEM source"] == "truth_plus_noise"
    _, grid = read_raster(out / "standin_dem_truth_plus_noise.tif")
    assert grid == info["grid"]


def test_both_heads_score_the_digitised_heads_alone_beside_them(tmp_path):
    """gully.heads: both (the Kamech sites' default) also writes Table 4 for the paper's procedure."""
    fabricate_twin(tmp_path / "tiny_twin" / "twin")
    cfg = yaml.safe_load(SITE.read_text())
    cfg["gully"]["heads"] = "both"
    cfg["gully"]["automatic_heads"]["dsm_sigma_z_m"] = 0.05  # the fabricated DSM's matching noise: no checkpoints read
    site = tmp_path / "both_site.yaml"
    site.write_text(yaml.safe_dump(cfg, sort_keys=False))
    out = tmp_path / "tiny_twin" / "gully"
    run_snakemake(site, tmp_path, [str(out / "network_validation.csv")],
                  extra=["--allowed-rules", *GULLY_RULES, "--nocolor"], cores=2)
    summary = dict(pd.read_csv(out / "gully_summary.csv").values)
    assert summary["head source (gully.heads)"] == "both"
    alone = pd.read_csv(out / "network_validation_digitised.csv")
    combined = pd.read_csv(out / "network_validation.csv")
    assert list(alone["category"]) == list(combined["category"])
    assert (out / "network_validation_tolerances_digitised.csv").exists()
    # the same reference; the detector's heads only add network, so they cannot lower the good fit
    assert alone["length_m"].iloc[0] == pytest.approx(combined["length_m"].iloc[0])
    fit = {name: dict(zip(t["category"], t["percent"]))["good_fit"] for name, t in (("alone", alone), ("both", combined))}
    assert 80 < fit["alone"] <= fit["both"] + 1e-6
    log = (tmp_path / "tiny_twin" / "logs" / "gully" / "validate.log").read_text()
    assert "digitised heads alone" in log
    # scored side by side in two threads: each log line names its network
    assert "all heads: reference:" in log and "digitised heads alone: reference:" in log


@pytest.mark.slow
@pytest.mark.xdist_group("tiny_sfm")  # shares the session's tiny-twin flight photos with the SfM rerun tests
def test_gully_stage_on_the_real_tiny_twin(tiny_flight, tmp_path):
    """SfM -> georeferencing -> dense DSM -> gully rules on the tiny twin's own photos (twin contract of issue 3).

    The gullies are mapped on the photogrammetric DSM of 12 images at 0.27 m GSD, far
    noisier than the default twin's (checkpoint SD about 0.3 m vs 0.05 m).
    """
    results = copy_results(tiny_flight, tmp_path / "results")
    out = results / "tiny_twin" / "gully"
    targets = [str(out / n) for n in ("gully_summary.csv", "network_validation.csv", "gully_area_scores.csv")]
    run_snakemake(SITE, results, [*targets, "--rerun-triggers", "mtime"], cores=2)
    summary = dict(pd.read_csv(out / "gully_summary.csv").values)
    assert summary["DEM source"] == "dense"
    assert (results / "tiny_twin" / "dense" / "dsm.tif").exists()
    assert not (out / "standin_dem_truth_plus_noise.tif").exists()
    assert summary["paths ending in a pit"] == "0"
    assert int(summary["heads on the DEM"]) > 0
    val = pd.read_csv(out / "network_validation.csv")
    pct = dict(zip(val["category"], val["percent"]))
    assert pct["good_fit"] + pct["false_negative"] == pytest.approx(100)
    # the traced network must find a substantial part of the field network on this noisy
    # DSM; the paper's target (>= 85 %) applies to the default site
    assert pct["good_fit"] > 50
    area = pd.read_csv(out / "gully_area_scores.csv").set_index("map_variant")
    assert {"precision", "recall", "iou"} <= set(area.columns)
    assert area.loc["buffer_and_patches", "iou"] > 0.05


TILED_GULLY_RULES = ["gully_depth_tile", "gully_depth_mosaic", "gully_trace_surface", "gully_fill_tile", "gully_fill_merge",
                     "gully_fill_mosaic"]


def fabricate_orthophoto(results: Path, grid: GridSpec) -> None:
    """``dense/orthophoto.tif``: soil colours, green foliage where the DSM stands > 0.15 m above the DTM (shrubs, crop)."""
    dsm, _ = read_raster(results / "dense" / "dsm.tif")
    dtm, _ = read_raster(results / "twin" / "truth" / "dtm.tif")
    rng = np.random.default_rng(3)
    soil = np.array([120.0, 110.0, 95.0])[:, None, None] + rng.normal(0.0, 3.0, (3, *dsm.shape))
    leaf = np.array([40.0, 90.0, 30.0])[:, None, None] + rng.normal(0.0, 3.0, (3, *dsm.shape))
    rgb = np.where((np.nan_to_num(dsm - dtm) > 0.15)[None], leaf, soil)
    rgb[:, ~np.isfinite(dsm)] = 0
    write_raster(results / "dense" / "orthophoto.tif", np.clip(rgb, 1, 255).astype(np.uint8), grid, nodata=0)


def test_tiled_site_with_crowns_maps_as_untiled(tmp_path):
    """gully.crowns on a tiled site (issue 21): crown mask and tracing surface in one job, tiled fill, same map.

    ``gully.edge_inlets`` is on too: the trunk leaves the DEM across its edge and no channel enters, so
    there is no inlet, tiled or not."""
    runs = {}
    for name, tiled in (("untiled", False), ("tiled", True)):
        results = tmp_path / name
        info = fabricate_twin(results / "tiny_twin" / "twin")
        fabricate_orthophoto(results / "tiny_twin", info["grid"])
        overlay = {"gully": {"crowns": {"enabled": True, "window_m": 1.0}, "edge_inlets": True,
                             "automatic_heads": {"dsm_sigma_z_m": 0.05}}}  # the fabricated DSM's stated noise
        if tiled:
            overlay["tiling"] = {"tile_m": 100.0, "extent": None}  # 2 x 2 tiles of the site's 200 m extent
        site = tmp_path / f"{name}.yaml"
        site.write_text(yaml.safe_dump(_merge(yaml.safe_load(SITE.read_text()), overlay)))
        out = results / "tiny_twin" / "gully"
        proc = run_snakemake(site, results, [str(out / "gully_summary.csv")],
                             extra=["--allowed-rules", *GULLY_RULES, *TILED_GULLY_RULES, "--printshellcmds"], cores=2)
        runs[name] = (out, proc.stdout + proc.stderr)
    (u, _), (t, log) = runs["untiled"], runs["tiled"]
    assert "rule gully_trace_surface:" in log and log.count("rule gully_fill_tile:") == 4
    crowns, _ = read_raster(t / "tiles" / "crown_mask.tif")
    assert 0 < int((crowns == 1).sum()) < crowns.size // 4  # shrubs and crop, not the field
    for raster in ("gully_map.tif", "gully_map_whole_patches.tif"):
        assert np.array_equal(read_raster(u / raster)[0], read_raster(t / raster)[0]), raster
    cu, ct = np.load(u / "gully_network_cells.npz"), np.load(t / "gully_network_cells.npz")
    assert all(np.array_equal(cu[k], ct[k]) for k in cu.files)
    su = dict(pd.read_csv(u / "gully_summary.csv").values)
    st = dict(pd.read_csv(t / "gully_summary.csv").values)
    assert {k: v for k, v in su.items() if "time" not in k and "(s)" not in k} == \
        {k: v for k, v in st.items() if "time" not in k and "(s)" not in k}
    assert int(su["channels entering across the DEM edge (edge_inlets)"]) == 0


def _merge(base: dict, overlay: dict) -> dict:
    out = dict(base)
    for k, v in overlay.items():
        out[k] = _merge(base.get(k, {}), v) if isinstance(v, dict) and isinstance(base.get(k), dict) else v
    return out
