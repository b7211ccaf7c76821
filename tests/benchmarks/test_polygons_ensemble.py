"""benchmarks/polygons_ensemble.py: member configs, skipped members and the mean/worst rows."""

from __future__ import annotations

import sys
from pathlib import Path

import pandas as pd

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "benchmarks"))

import polygons_ensemble as pe  # noqa: E402


def test_member_config_merges_the_override_on_the_default_site():
    d, e = pe.member_config("default"), pe.member_config("ens1")
    assert d["site"]["name"] == "kamech_twin" and e["site"]["name"] == "ens1"
    assert e["polygons"] == d["polygons"]  # the method is the default site's
    assert e["seed"] != d["seed"]


def test_a_held_out_twin_is_found_in_its_own_folder():
    h = pe.member_config("h1")
    assert h["site"]["name"] == "h1" and h["polygons"] == pe.member_config("default")["polygons"]


def test_a_member_without_a_dsm_is_skipped(tmp_path):
    row = pe.score_member("ens2", tmp_path)
    assert row["status"].startswith("skipped: no ") and row["status"].endswith("ens2/dense/dsm.tif")


def test_mean_and_worst_against_the_targets():
    df = pd.DataFrame([
        {"status": "ok", "iou_wide": 0.7, "width_med_abs_m": 0.8, "depth_med_abs_m": 0.1, "volume_error_pct": -5.0},
        {"status": "ok", "iou_wide": 0.5, "width_med_abs_m": 1.4, "depth_med_abs_m": 0.2, "volume_error_pct": 20.0},
        {"status": "skipped: no dsm"},
    ])
    s = pe.summarise(df).set_index("quantity")
    assert s.loc["iou_wide", "mean"] == 0.6 and s.loc["iou_wide", "worst"] == 0.5
    assert bool(s.loc["iou_wide", "mean meets"]) and not bool(s.loc["iou_wide", "worst meets"])
    assert s.loc["width_med_abs_m", "worst"] == 1.4 and not bool(s.loc["width_med_abs_m", "mean meets"])
    assert s.loc["volume_error_pct", "worst"] == 20.0 and bool(s.loc["volume_error_pct", "mean meets"])
    assert (s["members"] == 2).all()


def test_open_water_is_left_empty_as_on_a_photogrammetric_dsm(tmp_path):
    import numpy as np

    from kitegully.io.raster import GridSpec, Raster

    grid = GridSpec(500000.0, 4000100.0, 0.5, 6, 4, "EPSG:32632")
    lc = np.array([[3, 3, 8, 8, 3, 3]] * 4, np.uint8)
    Raster(lc, grid, 0).write(tmp_path / "landcover.tif")
    pd.DataFrame({"code": [3, 8], "name": ["grass", "water"]}).to_csv(tmp_path / "landcover_classes.csv", index=False)
    dem = Raster(np.arange(24, dtype=np.float32).reshape(4, 6), grid)
    out = pe.water_left_empty(dem, tmp_path)
    assert np.isnan(out.data[:, 2:4]).all() and np.array_equal(out.data[:, [0, 1, 4, 5]], dem.data[:, [0, 1, 4, 5]])
    assert not np.isnan(dem.data).any()  # the input is not changed


def test_set_overrides_merge_over_every_member():
    over = pe._merge(pe._dotted("polygons.morphometry.threshold_m", 0.25),
                     pe._dotted("polygons.conditioning.thresholds_m", [0.25, 0.5]))
    for m in ("default", "ens1", "h1"):
        c = pe.member_config(m, over)
        assert c["polygons"]["morphometry"]["threshold_m"] == 0.25
        assert c["polygons"]["conditioning"]["thresholds_m"] == [0.25, 0.5]
        # the rest of the section is the member's own
        assert c["polygons"]["morphometry"]["spacing_m"] == pe.member_config(m)["polygons"]["morphometry"]["spacing_m"]
    assert pe.member_config("default")["polygons"]["morphometry"]["threshold_m"] == 0.5  # no override, no change
