"""benchmarks/twin_ensemble.py: config merging, member list and the mean/worst rows."""

from __future__ import annotations

import sys
from pathlib import Path

import pandas as pd
import pytest

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "benchmarks"))

import twin_ensemble as te  # noqa: E402


def test_deep_merge_overrides_nested_keys_only():
    a = {"twin": {"texture": {"grass_greenness": 0.6, "x": 1}}, "seed": 1}
    b = {"twin": {"texture": {"grass_greenness": 0.1}}, "seed": 2}
    m = te.deep_merge(a, b)
    assert m == {"twin": {"texture": {"grass_greenness": 0.1, "x": 1}}, "seed": 2}
    assert a["twin"]["texture"]["grass_greenness"] == 0.6


def test_members_are_default_plus_five():
    names = [n for n, _ in te.members(None, te.BASE)]
    assert names[0] == "default" and len(names) == 6
    with pytest.raises(SystemExit, match="unknown ensemble member"):
        te.members(["nope"], te.BASE)


def test_held_out_twins_are_their_own_members_without_the_default():
    found = te.members(None, te.BASE, REPO / "config" / "sites" / "holdout")
    assert [n for n, _ in found] == [f"h{k}" for k in range(1, 33)]  # h27-h32: declared stress draws (session 43)
    cfgs = [te.deep_merge(te.yaml.safe_load(te.BASE.read_text()), te.yaml.safe_load(f[0].read_text())) for _, f in found]
    ens_seeds = {te.yaml.safe_load(f.read_text())["seed"] for _, files in te.members(None, te.BASE) for f in files}
    assert {c["seed"] for c in cfgs}.isdisjoint(ens_seeds | {2018})  # new draws, not an ensemble member's
    for c in cfgs:  # the snapping radius follows the claimed digitising error, as in the ensemble
        assert c["gully"]["head_snap_radius_m"] == pytest.approx(3 * c["twin"]["survey"]["heads_sigma_m"])


def test_extra_snakemake_arguments_reach_the_command(tmp_path, monkeypatch):
    seen = {}

    class Done:
        returncode = 0

    def fake_run(cmd, **_kw):
        seen["cmd"] = cmd
        return Done()

    monkeypatch.setattr(te.subprocess, "run", fake_run)
    te.run_snakemake([Path("a.yaml")], [Path("t")], 2, False, tmp_path / "log", "--rerun-triggers mtime --forcerun gully_map")
    cmd = seen["cmd"]
    i = cmd.index("--rerun-triggers")
    assert cmd[i:i + 4] == ["--rerun-triggers", "mtime", "--forcerun", "gully_map"]
    assert cmd.index("--configfile") > i + 3  # --configfile takes every argument after it: it stays last


def test_worst_row_takes_the_bad_side_of_each_column():
    df = pd.DataFrame({"member": ["a", "b"], "dig_good_fit_5m_pct": [90.0, 80.0], "dig_false_positive_5m_pct": [5.0, 9.0],
                       "camera_rmse_m": [0.2, 0.3], "checkpoint_mean_m": [0.05, -0.1], "dsm_coverage_pct": [99.0, 95.0]})
    s = te.summarise(df).set_index("member")
    assert s.loc["mean", "dig_good_fit_5m_pct"] == pytest.approx(85.0)
    assert s.loc["worst", "dig_good_fit_5m_pct"] == 80.0
    assert s.loc["worst", "dig_false_positive_5m_pct"] == 9.0
    assert s.loc["worst", "camera_rmse_m"] == 0.3
    assert s.loc["worst", "checkpoint_mean_m"] == -0.1
    assert s.loc["worst", "dsm_coverage_pct"] == 95.0


def test_change_rows_are_collected_and_their_worst_is_the_bad_side(tmp_path):
    cfg = te.yaml.safe_load(te.BASE.read_text())
    t = te.targets_for(cfg, tmp_path, change=True)
    assert t["change"] == tmp_path / cfg["site"]["name"] / te.CHANGE_TARGET
    assert "change" not in te.targets_for(cfg, tmp_path)
    t["change"].parent.mkdir(parents=True)
    rows = [(key, float(i)) for i, key in enumerate(te.CHANGE_ROWS.values())]
    pd.DataFrame(rows, columns=["quantity", "value"]).assign(unit="-").to_csv(t["change"], index=False)
    got = te.collect(cfg, {"change": t["change"], **{k: tmp_path / "missing" for k in te.TARGETS}}, tmp_path / "none")
    for i, col in enumerate(te.CHANGE_ROWS):
        assert got[col] == float(i)
    assert got["change_abs_net_error_pct"] == abs(got["change_net_error_pct"])
    df = pd.DataFrame({"member": ["a", "b"], "change_net_error_pct": [4.0, -30.0], "change_false_detection_pct": [0.7, 3.2],
                       "headcut_median_error_retreated_m": [0.6, 1.4], "moritani_b": [0.9, 0.8], "headcut_n_retreated": [8, 13]})
    s = te.summarise(df).set_index("member")
    assert s.loc["worst", "change_net_error_pct"] == -30.0  # signed: the largest |error|
    assert s.loc["worst", "change_false_detection_pct"] == 3.2
    assert s.loc["worst", "headcut_median_error_retreated_m"] == 1.4
    assert s.loc["worst", "moritani_b"] == 0.8
    assert pd.isna(s.loc["worst", "headcut_n_retreated"])  # counts are not scored


def test_regully_scores_three_head_sources_on_a_member_dsm(tmp_path):
    """--regully maps a member's DSM again for digitised, automatic and both heads (constructed member)."""
    import geopandas as gpd
    import numpy as np
    import shapely
    import yaml

    from kitegully.io.raster import GridSpec
    from kitegully.io.vectors import write_vector

    crs = "EPSG:32632"
    cell, n = 0.2, 400
    grid = GridSpec(500000.0, 4000000.0 + n * cell, cell, n, n, crs)
    xs, ys = grid.cell_centres()
    X, Y = np.meshgrid(xs - xs[0], ys - ys[-1])
    # a 10 % slope draining south into a hollow with a 1 m deep, 2 m wide V channel from y = 60 m down
    z = 0.1 * Y + 0.05 * np.abs(X - 40.0)
    z = z - 1.0 * np.clip(1 - np.abs(X - 40.0), 0, None) * np.clip((60.0 - Y) / 0.4, 0, 1)
    z = (z + np.random.default_rng(0).normal(0, 0.01, z.shape)).astype(np.float32)
    twin = tmp_path / "twin"
    line = shapely.LineString([(xs[0] + 40.0, ys[-1] + 60.0), (xs[0] + 40.0, ys[-1])])
    head = shapely.Point(line.coords[0])
    write_vector(gpd.GeoDataFrame({"head_id": [1]}, geometry=[shapely.Point(head.x + 1.5, head.y - 1.0)], crs=crs),
                 twin / "observed/gully_heads.gpkg")
    rng = np.random.default_rng(1)
    cx, cy = rng.uniform(5, 30, 50), rng.uniform(5, 75, 50)
    pd.DataFrame({"id": np.arange(50), "x": xs[0] + cx, "y": ys[-1] + cy,
                  "z": 0.1 * cy + 0.05 * np.abs(cx - 40.0)}).to_csv(twin / "observed/checkpoints.csv", index=False)
    ref = gpd.GeoDataFrame({"gully_no": [1]}, geometry=[line], crs=crs)
    polys = gpd.GeoDataFrame({"gully_id": [1]}, geometry=[line.buffer(1.0)], crs=crs)
    # the member's orthophoto (the site's gully.crowns reads it): bare brown soil, no crowns
    import rasterio

    (tmp_path / "dense").mkdir()
    with rasterio.open(tmp_path / "dense/orthophoto.tif", "w", driver="GTiff", width=n, height=n, count=3, dtype="uint8",
                       crs=crs, transform=grid.transform) as dst:
        for b, v in enumerate((150, 110, 80)):
            dst.write(np.clip(v + rng.normal(0, 3, (n, n)), 1, 255).astype(np.uint8), b + 1)
    g = yaml.safe_load((te.BASE).read_text())["gully"]
    out = te.regully_member(g, twin, z, grid, ref, polys, np.array([[head.x, head.y]]), crs)
    for key in ("dig", "auto", "both"):
        assert {f"{key}_good_fit_5m_pct", f"{key}_false_positive_5m_pct", f"{key}_iou", f"{key}_n_heads"} <= set(out)
    assert out["dig_n_heads"] == 1
    assert out["dig_good_fit_5m_pct"] > 90
    assert out["auto_n_heads"] >= 1 and out["auto_good_fit_5m_pct"] > 90
    # the automatic head of this channel lies within the snapping radius of the digitised one: not added again
    assert out["both_n_heads"] == 1
    assert out["dig_iou"] > 0.2
    # a member whose rule mapped with gully.heads: both (the Kamech default) is scored the same way
    # without --regully: its rule products hold no map of the digitised heads alone
    from kitegully.io.raster import write_raster

    write_raster(tmp_path / "dense/dsm.tif", z, grid)
    write_vector(ref, twin / "observed/field_network.gpkg")
    write_vector(polys, twin / "truth/gully_polygons.gpkg")
    write_vector(gpd.GeoDataFrame({"head_id": [1]}, geometry=[head], crs=crs), twin / "truth/gully_heads.gpkg")
    assert g["heads"] == "both"
    collected = te.score_heads_both({"gully": g, "site": {"crs": crs}}, tmp_path)
    for key in ("dig", "auto", "both"):
        assert collected[f"{key}_good_fit_5m_pct"] == pytest.approx(out[f"{key}_good_fit_5m_pct"])
