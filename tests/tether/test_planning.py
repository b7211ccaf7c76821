"""Flight planner: the paper's camera and geometry."""

import math

import pytest

from kitegully.tether.planning import PlanningCamera, line_length_for_angle, plan_flight, stereo_precision_m

NEX5N = PlanningCamera(23.4, 15.6, 4912, 3264, 18.0)


def test_gsd_and_footprint_of_the_paper_camera():
    assert NEX5N.pixel_pitch_m == pytest.approx(4.76e-6, rel=0.01)
    assert NEX5N.gsd_m(500.0) == pytest.approx(0.13, rel=0.03)  # Table 2: max pixel 0.13 m
    across, along = NEX5N.footprint_m(500.0)
    assert across == pytest.approx(650.0, rel=1e-9)
    assert along == pytest.approx(433.3, rel=1e-3)


def test_plan_rows():
    plan = plan_flight(NEX5N, [120, 300, 500], 50.0, 5.0, 1.0, 0.6, max_flying_height_m=500)
    assert list(plan.columns[:8]) == [
        "line_length_m", "flying_height_m", "gsd_m", "footprint_across_m", "footprint_along_m",
        "forward_overlap", "base_height_ratio", "precision_z_m",
    ]
    top = plan.iloc[-1]
    assert top.line_length_m == pytest.approx(500 / math.sin(math.radians(50)))  # 653 m, not 600 m
    assert top.forward_overlap == pytest.approx(1 - 5.0 / 433.33, rel=1e-3)
    assert top.stereo_base_m <= 0.4 * top.footprint_along_m
    assert top.precision_z_m == pytest.approx(stereo_precision_m(500, top.stereo_base_m, NEX5N))
    # eq. 1 by hand: (H/f)(H/B) p
    assert top.precision_z_m == pytest.approx((500 / 0.018) * (500 / top.stereo_base_m) * 23.4e-3 / 4912)
    assert top.downwind_offset_m == pytest.approx(math.sqrt(top.line_length_m**2 - 500**2))


def test_target_gsd_caps_the_heights():
    plan = plan_flight(NEX5N, [120, 300, 500], 50.0, 5.0, 1.0, 0.6, target_gsd_m=0.08)
    assert plan["flying_height_m"].max() == 300
    assert (plan["gsd_m"] <= 0.08).all()
    with pytest.raises(ValueError, match="no flying height"):
        plan_flight(NEX5N, [120, 300], 50.0, 5.0, 1.0, 0.6, target_gsd_m=0.01)


def test_line_length_and_bad_angles():
    assert line_length_for_angle(500, 90 - 1e-9) == pytest.approx(500)
    with pytest.raises(ValueError):
        plan_flight(NEX5N, [100], 95.0, 5.0, 1.0, 0.6)
    assert math.isinf(stereo_precision_m(100, 0, NEX5N))
