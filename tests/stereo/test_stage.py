"""The stereo stage: parameters, the rain model's maths and the entry points on a tiny configuration."""

import copy
import json

import numpy as np
import pandas as pd
import pytest
import yaml

from kitegully import InputError
from kitegully.stereo.stage import (StereoParams, calibrate_rig, interrill_rate_kg_m2_h, measure_dry_box, measure_rain,
                                    measure_wind, settlement_mm)

SITE = "config/sites/stereo_lab.yaml"


@pytest.fixture(scope="module")
def cfg(request):
    root = request.config.rootpath
    return yaml.safe_load((root / SITE).read_text())["stereo"]


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


def test_params_from_site_file_and_bad_keys(cfg):
    p = StereoParams.from_config(cfg)
    assert p.calibration["field_sigma_mm"] == 0.2 and len(p.dry_box["setups"]) == 11
    bad = copy.deepcopy(cfg)
    bad["rain"]["drop_size"] = 2
    with pytest.raises(InputError, match="stereo.rain: unknown key 'drop_size'"):
        StereoParams.from_config(bad)
    bad = copy.deepcopy(cfg)
    bad["rain"]["bulk_densities"] = [0.91, 1.3]
    with pytest.raises(InputError, match=r"stereo.rain.bulk_densities: 1.3 g/cm³ must lie between 0 and seal_density \(1.2\)"):
        StereoParams.from_config(bad)
    bad = copy.deepcopy(cfg)
    bad["calibration"]["stations"] = "many"
    with pytest.raises(InputError, match="stereo.calibration.stations: must be one of paper, paper\\+convergent, paper\\+convergent\\+corners"):
        StereoParams.from_config(bad)


def test_runoff_detachment_grows_downslope_above_the_threshold():
    from kitegully.stereo.stage import runoff_detachment_kg_m2_h

    y = np.array([0.0, 0.25, 0.5])
    tau, D = runoff_detachment_kg_m2_h(y, 60.0, 2.41, 10.0, 0.03, 0.0069, 3.5)
    # q = 57.59 mm/h · 0.5 m = 8.0e-6 m²/s; h = (0.03 q / √sin10°)^0.6 = 0.18 mm; τ = ρ g h sin10° = 0.31 Pa
    assert tau[2] == pytest.approx(1000 * 9.81 * (0.03 * 57.59e-3 / 3600 * 0.5 / np.sqrt(np.sin(np.radians(10)))) ** 0.6
                                   * np.sin(np.radians(10)), rel=1e-9)
    assert tau[2] == pytest.approx(0.307, abs=0.005) and (D == 0).all()
    _, D0 = runoff_detachment_kg_m2_h(y, 60.0, 2.41, 10.0, 0.03, 0.0069, 0.0)
    assert D0[0] == 0 and D0[1] < D0[2]  # no threshold: erosion grows with the runoff, downstream more
    _, Dn = runoff_detachment_kg_m2_h(y, 2.0, 2.41, 10.0, 0.03, 0.0069, 0.0)
    assert (Dn == 0).all()  # Ksat > I: no runoff


def test_settlement_and_interrill_maths():
    assert settlement_mm(0.91, 10.0, 1.20) == pytest.approx(10 * (1 - 0.91 / 1.2))
    assert settlement_mm(1.25, 10.0, 1.20) == 0.0
    # WEPP: D_i = K_i I^2 S_f, I = 60 mm/h, 10 deg: S_f = 1.05 - 0.85 exp(-4 sin 10°) = 0.6256
    Sf = 1.05 - 0.85 * np.exp(-4 * np.sin(np.radians(10)))
    assert interrill_rate_kg_m2_h(1e6, 60.0, 10.0) == pytest.approx(1e6 * (60e-3 / 3600) ** 2 * Sf * 3600)
    assert interrill_rate_kg_m2_h(1e6, 60.0, 10.0) == pytest.approx(0.626, abs=0.001)


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


def test_error_decomposition_on_constructed_surfaces():
    from kitegully.io.raster import GridSpec
    from kitegully.stereo.stage import error_decomposition

    grid = GridSpec(x0=-0.1, y0=0.1, cell=0.01, width=20, height=20, crs="EPSG:32632")
    X, Y = np.meshgrid(*grid.cell_centres())
    ref = 0.003 * np.sin(40 * X)
    noise = np.where((np.indices(X.shape).sum(axis=0) % 2) == 0, 1e-4, -1e-4)  # ±0.1 mm, zero mean, no tilt
    dem = ref + 2e-4 + 1e-3 * Y + noise  # 0.2 mm offset, 1 mm/m tilt
    dem[0, 0] = np.nan
    d = error_decomposition(dem, ref, grid)
    assert d["tilt_mm_per_m"] == pytest.approx(1.0, abs=0.02)
    assert d["residual_mae_mm"] == pytest.approx(0.1, abs=0.005)
    assert d["mean_error_mm"] == pytest.approx(0.2 + 1e3 * 1e-3 * np.nanmean(np.where(np.isfinite(dem), Y, np.nan)), abs=0.01)


def test_matching_residual_measures_a_known_disparity_error():
    """Disparity = ray-cast truth + N(0.2 px bias, 0.05 px) → the measured δ and bias are those values."""
    from kitegully.io.raster import GridSpec
    from kitegully.stereo.matching import Disparity
    from kitegully.stereo.rectify import rectify_pair, relative_orientation_from_poses
    from kitegully.stereo.rig import paper_rig
    from kitegully.stereo.stage import matching_residual_px

    rig = paper_rig(2.7, 0.8)
    R, T = relative_orientation_from_poses(rig.pose_left, rig.pose_right)
    rect = rectify_pair(rig.left, rig.right, R, T, (2.6, 2.8))
    h = lambda x, y: 0.004 * np.sin(2 * np.pi * x / 0.12)  # noqa: E731
    # ray-cast the true disparity of every left rectified pixel over the box
    W, H_ = rect.size
    yy, xx = np.mgrid[0:H_, 0:W].astype(float)
    sel = (slice(600, 1100), slice(900, 1500))
    xs, ys = xx[sel].ravel(), yy[sel].ravel()
    P1 = rect.P1
    dirs = np.column_stack([(xs - P1[0, 2]) / P1[0, 0], (ys - P1[1, 2]) / P1[1, 1], np.ones_like(xs)])
    dw = (dirs @ rect.R1) @ rig.pose_left.R
    C = rig.pose_left.C
    t = -C[2] / dw[:, 2]
    for _ in range(8):
        Xw = C + t[:, None] * dw
        t = (h(Xw[:, 0], Xw[:, 1]) - C[2]) / dw[:, 2]
    Xw = C + t[:, None] * dw
    ur = rect.rectify_points(rig.right.project(Xw, rig.pose_right), "right")
    d = np.full((H_, W), np.nan)
    rng = np.random.default_rng(1)
    d[sel] = (xs - ur[:, 0] + 0.2 + rng.normal(0, 0.05, xs.size)).reshape(d[sel].shape)
    grid = GridSpec(x0=-0.05, y0=0.05, cell=0.005, width=20, height=20, crs="EPSG:32632")
    m = matching_residual_px(rect, Disparity(d, np.ones_like(d)), rig, h, grid)
    assert m["n"] > 2000
    assert m["bias_d_px"] == pytest.approx(0.2, abs=0.01)
    # bilinear interpolation of independent pixel errors averages them a little: σ between 0.5 and 1.0 × 0.05
    assert 0.025 < m["sigma_d_px"] < 0.052
    assert m["y_parallax_rms_px"] < 1e-6  # true orientation: no vertical parallax


def test_surface_consistent_drops_a_false_match_along_the_epipolar_line():
    from kitegully.stereo.stage import surface_consistent

    rng = np.random.default_rng(0)
    uv = rng.uniform(0, 400, (500, 2))
    d = -150 + 0.05 * uv[:, 0] + np.where(uv[:, 1] > 200, 6.0, 0.0)  # a tilted surface with a 6 px step (a rim)
    d[7] = 55.0  # the right row, the wrong place: it fits the coplanarity condition
    keep = surface_consistent(uv, d, 10.0)
    assert not keep[7] and keep.sum() == 499
    assert surface_consistent(uv[:5], d[:5], 10.0).all()  # too few ties to judge: all kept
