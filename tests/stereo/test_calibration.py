import numpy as np
import pytest

from kitegully import InputError
from kitegully.stereo.calibration import calibrate_camera, calibration_table
from kitegully.stereo.control_field import (ControlField, Observation, calibration_field, calibration_poses, simulate_observations)
from kitegully.stereo.rig import D2H_PIXEL_MM, camera_to_table, paper_cameras


def test_noise_free_calibration_recovers_intrinsics():
    cams = paper_cameras()
    field, poses = calibration_field(), calibration_poses()
    results = {}
    for side, cam in cams.items():
        obs = simulate_observations(cam, field, poses)
        assert len(obs) == 6
        results[side] = calibrate_camera(field, obs, cam.width, cam.height, D2H_PIXEL_MM, template=cam, name=side)
        rec, tru = camera_to_table(results[side].camera), camera_to_table(cam)
        assert abs(rec["f_mm"] - tru["f_mm"]) < 0.05  # issue target, mm
        assert abs(rec["K1"] - tru["K1"]) < 0.10 * abs(tru["K1"])
        assert abs(rec["x0_mm"] - tru["x0_mm"]) < 0.0094  # well under one pixel
        assert results[side].rms_px < 1e-3
    table = calibration_table(results, cams)
    assert len(table) == 10 and set(table["camera"]) == {"left", "right"}
    assert (table.loc[table.parameter == "f", "paper"].to_numpy() == [51.4, 51.5]).all()


def test_point_seen_once_is_rejected():
    cam = paper_cameras()["left"]
    field, poses = calibration_field(), calibration_poses()
    obs = simulate_observations(cam, field, poses)
    keep = obs[0].ids[0]
    obs = [obs[0]] + [Observation(o.ids[o.ids != keep], o.uv[o.ids != keep]) for o in obs[1:]]
    with pytest.raises(InputError, match=f"left: calibration point '{keep}' is seen in only one image"):
        calibrate_camera(field, obs, cam.width, cam.height, D2H_PIXEL_MM, name="left")


def test_unknown_target_and_too_few_points():
    cam = paper_cameras()["left"]
    field, poses = calibration_field(), calibration_poses()
    obs = simulate_observations(cam, field, poses)
    bad = [Observation(np.where(o.ids == o.ids[0], "X99", o.ids), o.uv) for o in obs]
    with pytest.raises(InputError, match="measures target 'X99', which is not in the control field"):
        calibrate_camera(field, bad, cam.width, cam.height, D2H_PIXEL_MM)
    few = [Observation(o.ids[:5], o.uv[:5]) for o in obs]
    with pytest.raises(InputError, match="sees 5 targets; each image needs at least 6"):
        calibrate_camera(field, few, cam.width, cam.height, D2H_PIXEL_MM)


def test_weighted_control_bundle_absorbs_field_error():
    """Convergent + shifted stations with the field as weighted observations: f within the issue's 0.05 mm
    where the paper's protocol (6 shifted images, field held fixed) misses it."""
    from kitegully.seeds import rng_for
    from kitegully.stereo.calibration import calibrate_camera_weighted
    from kitegully.stereo.control_field import convergent_poses

    cam = paper_cameras()["left"]
    field = calibration_field()
    rng = rng_for(3, "test", "weighted")
    known = ControlField(field.ids, field.xyz + rng.normal(0.0, 2e-4, field.xyz.shape))
    f_true = camera_to_table(cam)["f_mm"]
    paper = simulate_observations(cam, field, calibration_poses(), 0.1, rng)
    fixed = calibrate_camera(known, paper, cam.width, cam.height, D2H_PIXEL_MM, template=cam)
    obs = simulate_observations(cam, field, calibration_poses() + convergent_poses(), 0.1, rng)
    res, xyz = calibrate_camera_weighted(known, obs, cam.width, cam.height, D2H_PIXEL_MM, 0.1, 2e-4, template=cam)
    # a hard draw for the paper's protocol (|df| 0.27 mm with the field held fixed); the bound tests the
    # mechanism (weighted control much better than fixed), the 0.05 mm target is checked over 16 draws in the README
    df_w = abs(camera_to_table(res.camera)["f_mm"] - f_true)
    df_fixed = abs(camera_to_table(fixed.camera)["f_mm"] - f_true)
    assert df_w < 0.06 and df_w < 0.3 * df_fixed
    # the adjusted targets moved towards the truth
    assert np.sqrt(np.mean((xyz - field.xyz) ** 2)) < np.sqrt(np.mean((known.xyz - field.xyz) ** 2))
    # K1 comes with a standard error that covers its error; K1 and K2 are strongly anti-correlated, and the
    # corner displacement they make together is known far better than K1 alone
    from kitegully.stereo.calibration import distortion_precision

    d = distortion_precision(res, cam)
    assert res.covariance.shape == (5, 5)
    assert abs(d["K1_err_in_se"]) < 3.5 and d["corr_K1_K2"] < -0.8
    assert 0.02 < d["edge_dr_se_px"] < 0.3 and abs(d["edge_dr_err_px"]) < 4 * d["edge_dr_se_px"]
    assert d["edge_dr_px"] == pytest.approx(3.3, abs=0.3)  # 7.6e-6·13.9³ + 2e-8·13.9⁵ mm = 3.3 px at the corner
    with pytest.raises(InputError, match="the calibration has no covariance"):
        distortion_precision(fixed)
    with pytest.raises(InputError, match="camera: sigma_px = 0.0 and sigma_field_m = 0.0002 must both be positive"):
        calibrate_camera_weighted(known, obs, cam.width, cam.height, D2H_PIXEL_MM, 0.0, 2e-4)



def test_corner_images_make_the_right_cameras_k1_identifiable():
    """The stage's stations (6 shifted + 8 aimed convergent) hardly reach the frame corners; 8 more convergent
    images with the field turned half-way to a corner (stations paper+convergent+corners) put far more targets
    beyond 0.8 of the half-diagonal and shrink K1's standard error on the right camera, whose K1 moves a corner
    by only 0.4 px. Targets at 0.01 px, the rendered targets' bundle RMS."""
    from kitegully.seeds import rng_for
    from kitegully.stereo.calibration import calibrate_camera_weighted, distortion_precision
    from kitegully.stereo.control_field import convergent_poses

    cam = paper_cameras()["right"]
    field = calibration_field()
    known = ControlField(field.ids, field.xyz + rng_for(4, "test", "corners").normal(0.0, 2e-4, field.xyz.shape))
    stage = calibration_poses() + convergent_poses()
    rmax = np.hypot(cam.width / 2, cam.height / 2)
    out = {}
    for name, poses in (("stage", stage), ("corners", stage + convergent_poses(corner_fraction=0.5))):
        obs = simulate_observations(cam, field, poses, 0.01, rng_for(4, "test", "corner targets"))
        far = sum(int((np.hypot(o.uv[:, 0] - cam.cx, o.uv[:, 1] - cam.cy) / rmax > 0.8).sum()) for o in obs)
        res, _ = calibrate_camera_weighted(known, obs, cam.width, cam.height, D2H_PIXEL_MM, 0.01, 2e-4, template=cam)
        out[name] = (far, distortion_precision(res, cam), camera_to_table(res.camera)["f_mm"] - camera_to_table(cam)["f_mm"])
    assert out["corners"][0] >= 1.5 * out["stage"][0]
    se = {k: v[1]["K1_se"] for k, v in out.items()}
    assert se["corners"] < 0.8 * se["stage"]
    assert abs(out["corners"][1]["K1_err_pct"]) < 10.0 and abs(out["corners"][2]) < 0.05
