import pytest

from kitegully import InputError
from kitegully.stereo.rig import (PAPER_TABLE1, camera_to_table, delta_z_m, paper_cameras, paper_rig,
                                  radial_mm_to_normalised, radial_normalised_to_mm)


def test_paper_cameras_round_trip_table1():
    cams = paper_cameras()
    for side, cam in cams.items():
        assert (cam.width, cam.height) == (2464, 1632)
        assert cam.pixel_pitch_mm == pytest.approx(0.0094)
        back = camera_to_table(cam)
        for k, v in PAPER_TABLE1[side].items():
            assert back[k] == pytest.approx(v, rel=1e-9, abs=1e-12)


def test_radial_conversion_matches_mm_model():
    f = 51.4
    K1, K2 = 7.6e-6, 2.0e-8
    k1, k2 = radial_mm_to_normalised(K1, K2, f)
    r_mm = 10.0
    rn = r_mm / f
    # Δr in mm from the paper's model equals f·(x_d − x) of the normalised model
    assert f * rn * (k1 * rn**2 + k2 * rn**4) == pytest.approx(K1 * r_mm**3 + K2 * r_mm**5, rel=1e-12)
    assert radial_normalised_to_mm(k1, k2, f) == pytest.approx((K1, K2))


def test_delta_z_reuses_planner_formula():
    cam = paper_cameras()["left"]
    # L·δ/f with the calibrated principal distance: 9.1125 m · 0.0094 / 51.4
    # δz = L·δ/f (m): 9.1125 m · 0.0094 mm / 51.4 mm = 1.67 mm (the paper's 0.19 mm per m of L at f = 50 mm)
    assert delta_z_m(2.7, 0.8, cam) == pytest.approx(9.1125 * 0.0094 / 51.4, rel=1e-9)
    assert delta_z_m(2.7, 0.8, cam, matching_px=0.1) == pytest.approx(0.1 * delta_z_m(2.7, 0.8, cam))


def test_rig_geometry_and_bad_input():
    rig = paper_rig(2.7, 0.8)
    assert rig.base_m == pytest.approx(0.8)
    assert rig.height_m() == pytest.approx(2.7)
    with pytest.raises(InputError, match="must both be positive"):
        paper_rig(2.7, 0.0)
