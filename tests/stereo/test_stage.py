"""The stereo stage's entry points on a tiny configuration, and a bad camera file."""

import copy
import json

import pandas as pd
import pytest

from kitegully import InputError
from kitegully.stereo import calibrate_rig, measure_dry_box, measure_rain, measure_wind


def tiny(cfg):
    """A tiny configuration: paper stations, fixed control, rigs high enough that the box is a few hundred pixels."""
    c = copy.deepcopy(cfg)
    c["calibration"].update(stations="paper", weighted_control=False)
    c["calibration_test"]["H_m"] = [2.0, 4.0]
    c["dry_box"].update(setups=[[4.7, 0.8], [4.7, 0.63]], removals=2, removal_H_m=4.7, removal_B_m=0.8)
    c["rain"].update(bulk_densities=[0.91], duration_min=10.0, interval_min=10.0, H_m=4.7, B_m=0.8)
    c["wind"].update(H_m=3.0, B_m=1.0, mark_diameter_mm=10.0)  # the tray's 2 mm marks would be 3.6 px across at H 3 m
    # the tiny run checks the removal maths with one orientation for all epochs (with marks located in the
    # photographs a re-orientation moves the box by only ~0.01 mm; at an assumed 0.2 px it was ~0.4 mm at L = 28 m)
    c["processing"]["reorient_each_pair"] = False
    return c


def test_entry_points_on_a_tiny_configuration(cfg, tmp_path):
    c = tiny(cfg)
    o = {k: str(tmp_path / v) for k, v in {"calibration": "calibration.csv", "cameras": "cameras.json", "test": "test.csv",
                                             "test_png": "test.png"}.items()}
    calibrate_rig({k: c[k] for k in ("calibration", "calibration_test")}, 7, o)
    tab = pd.read_csv(o["calibration"])
    assert len(tab) == 10 and {"recovered", "recovered_paper_protocol", "truth", "paper"} <= set(tab.columns)
    assert json.loads(open(o["cameras"]).read())["left"]["width"] == 2464
    test = pd.read_csv(o["test"])
    with_io = test[test.processing == "with inner orientation"]["mae_z_mm"].to_numpy()
    without = test[test.processing == "without inner orientation"]["mae_z_mm"].to_numpy()
    assert (with_io < without).all()  # the inner orientation matters
    d = {k: str(tmp_path / f"{k}.{'png' if k.endswith('png') else 'csv'}") for k in ("mae_vs_L", "mae_vs_L_png", "removals", "removals_png", "dod_png")}
    measure_dry_box({k: c[k] for k in ("processing", "dry_box")}, o["cameras"], 7, d)
    mv = pd.read_csv(d["mae_vs_L"])
    assert len(mv) == 2 and (mv["surface_mae_mm"] < 0.5 * mv["dz_1px_mm"]).all()  # well under the 1-px δz (6.4 mm)
    # the matcher's precision measured against the twin's surface: a small fraction of a pixel
    assert (mv["sigma_d_px"] > 0.01).all() and (mv["sigma_d_px"] < 0.2).all()
    assert (mv["surface_residual_mae_mm"] <= mv["surface_mae_mm"] + 1e-9).all()
    rem = pd.read_csv(d["removals"])
    assert len(rem) == 2 and rem["M_s_mm"].iloc[0] == pytest.approx(50 / 1500 * 10, rel=0.01)  # 50 mL over 1500 cm²
    assert abs(rem["b_fit"].iloc[0] - 1) < 0.2
    r = {k: str(tmp_path / f"{k}.{'png' if 'png' in k else 'csv'}") for k in ("rain_runs", "rain_series", "dod_png_0")}
    measure_rain({k: c[k] for k in ("processing", "rain")}, o["cameras"], 7, r)
    rr = pd.read_csv(r["rain_runs"])
    # the DEM lowering includes the settlement, the gravimetric depth does not
    assert rr["A_s_final_mm"].iloc[0] > rr["M_s_final_mm"].iloc[0]
    # WEPP thresholds: the sheet flow of a 0.5 m box stays far below τ_c, so the model's upstream-downstream difference is 0
    assert rr["flow_shear_max_pa"].iloc[0] < 0.2 * rr["critical_shear_pa"].iloc[0]
    assert rr["upstream_minus_downstream_model_mm"].iloc[0] == 0.0
    w = {"wind_run": str(tmp_path / "wind.csv"), "dod_png": str(tmp_path / "wind.png")}
    measure_wind({k: c[k] for k in ("processing", "wind")}, o["cameras"], 7, w)
    assert pd.read_csv(w["wind_run"])["MAE_nails_mm"].iloc[0] < 0.5


def test_bad_camera_file_gives_one_sentence(cfg, tmp_path):
    bad = tmp_path / "cams.json"
    bad.write_text(json.dumps({"left": {}}))
    with pytest.raises(InputError, match="not a calibrated stereo camera file"):
        measure_wind({k: tiny(cfg)[k] for k in ("processing", "wind")}, str(bad), 7, {})
