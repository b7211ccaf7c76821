"""Line model: analytic limits, monotonic behaviour and the paper's Table 2."""

import numpy as np
import pytest

from kitegully.tether.line import (
    Atmosphere,
    FlightStatus,
    Kite,
    KiteModel,
    LineMaterial,
    kite_position,
    line_length_for_height,
    positions_for_lengths,
    solve_line,
)

ATM = Atmosphere(1.18, 9.81)
KITE = Kite("delta10", 8.7, 0.15, 60.0, 2.7, 0.5)
DYNEEMA = LineMaterial("dyneema", 0.8e-3, 0.39e-3, 870.0)
POLYESTER = LineMaterial("polyester", 2.5e-3, 3.0e-3, 590.0)
WINDS = [5.0, 7.0, 9.0, 11.0]


def test_weightless_dragless_line_is_straight_along_kite_force():
    ideal = LineMaterial("ideal", 0.0, 0.0)
    sol = solve_line(ideal, KITE, [3.0, 7.0], 500.0, ATM)
    for w in range(2):
        x, z = sol.shape(w, 500.0)
        angles = np.degrees(np.arctan2(z[1:], x[1:]))
        np.testing.assert_allclose(angles, 60.0, atol=1e-9)
        assert sol.position(w, 500.0).height_m == pytest.approx(500.0 * np.sin(np.radians(60)), rel=1e-12)


def test_line_without_wind_load_is_the_closed_form_catenary():
    # No drag on the line: horizontal tension H is constant and the line is a catenary.
    heavy = LineMaterial("heavy", 2.5e-3, 0.01, drag_coefficient=0.0)
    kite = Kite("k", 8.7, 0.15, 45.0)
    wind, length = 7.0, 300.0
    sol = solve_line(heavy, kite, [wind], length, ATM)
    h_tension = 0.5 * ATM.air_density_kg_m3 * kite.area_m2 * wind**2 * kite.drag_coefficient
    v_top = h_tension * np.tan(np.radians(kite.pull_angle_deg))
    w = heavy.linear_mass_kg_m * ATM.gravity_m_s2
    a = h_tension / w
    s = np.arange(0, length + 1.0)  # arc length below the kite
    v = v_top - w * s
    assert v[-1] > 0, "test case must stay airborne"
    # Node positions relative to the kite (x downwind, z up), from the catenary in arc length.
    x_exact = -a * (np.arcsinh(v_top / h_tension) - np.arcsinh(v / h_tension))
    z_exact = -a * (np.sqrt(1 + (v_top / h_tension) ** 2) - np.sqrt(1 + (v / h_tension) ** 2))
    drop = abs(z_exact[-1])
    sag = np.max(np.abs(z_exact - x_exact * z_exact[-1] / x_exact[-1]))
    assert sag > 0.02 * drop, "test case must have a visible sag"
    np.testing.assert_allclose(sol.x[0], x_exact, atol=0.01 * drop)
    np.testing.assert_allclose(sol.z[0], z_exact, atol=0.01 * drop)
    # The sag itself (deviation from the chord) is also right within 1 % of its size.
    model_sag = np.max(np.abs(sol.z[0] - sol.x[0] * sol.z[0, -1] / sol.x[0, -1]))
    assert model_sag == pytest.approx(sag, rel=0.01)


@pytest.mark.parametrize("material", [DYNEEMA, POLYESTER], ids=lambda m: m.name)
def test_flight_angle_falls_with_line_length(material):
    lengths = np.arange(50.0, 701.0, 50.0)
    sol = solve_line(material, KITE, WINDS, 700.0, ATM)
    for row in positions_for_lengths(sol, lengths):
        angles = np.array([p.flight_angle_deg for p in row])
        assert np.all(np.diff(angles) < 0)
        assert np.all(angles < KITE.pull_angle_deg)


def test_polyester_sags_more_than_dyneema():
    lengths = np.array([150.0, 360.0, 600.0])
    dy = positions_for_lengths(solve_line(DYNEEMA, KITE, WINDS, 600.0, ATM), lengths)
    po = positions_for_lengths(solve_line(POLYESTER, KITE, WINDS, 600.0, ATM), lengths)
    for row_d, row_p in zip(dy, po):
        drop_d = row_d[0].flight_angle_deg - row_d[-1].flight_angle_deg
        drop_p = row_p[0].flight_angle_deg - row_p[-1].flight_angle_deg
        assert drop_p > 2 * drop_d
        assert all(p.flight_angle_deg < d.flight_angle_deg for p, d in zip(row_p, row_d))


def test_table2_heights_with_dyneema_under_reading_IA():
    # Feurer et al. 2018 Table 2: 150 / 360 / 600 m of line -> 120 / 300 / 500 m.
    sol = solve_line(DYNEEMA, KITE, WINDS, 600.0, ATM)
    for row in positions_for_lengths(sol, np.array([150.0, 360.0, 600.0])):
        assert row[1].height_m == pytest.approx(300.0, rel=0.05)
        assert row[2].height_m == pytest.approx(500.0, rel=0.05)
        # Finding, not tuned: at 150 m even the 60° chord of a perfect line gives 130 m, so
        # the paper's rounded 120 m cannot be met; the model lies between the two.
        assert 120.0 < row[0].height_m < 150.0 * np.sin(np.radians(60.0))


def test_reading_IB_cannot_fly_in_light_wind():
    kite_b = Kite("delta10", 8.7, 0.15, 60.0, 2.7, 0.5, KiteModel.AERO_RESULTANT)
    assert kite_position(DYNEEMA, kite_b, 3.0, 150.0, ATM).status is FlightStatus.CANNOT_FLY
    low = kite_position(DYNEEMA, kite_b, 5.0, 150.0, ATM)
    assert low.status is FlightStatus.FLYING and low.flight_angle_deg < 15.0
    assert kite_position(DYNEEMA, kite_b, 5.0, 600.0, ATM).status is FlightStatus.LINE_ON_GROUND


def test_heavy_line_in_light_wind_lies_on_the_ground_and_has_no_shape():
    sol = solve_line(POLYESTER, KITE, [3.0], 700.0, ATM)
    pos = sol.position(0, 600.0)
    assert pos.status is FlightStatus.LINE_ON_GROUND
    assert pos.grounded_length_m > 0 and np.isnan(pos.flight_angle_deg)
    with pytest.raises(ValueError, match="line_on_ground"):
        sol.shape(0, 600.0)
    assert sol.position(0, 150.0).status is FlightStatus.FLYING


def test_line_length_for_height_inverts_the_solution():
    sol = solve_line(DYNEEMA, KITE, [7.0], 900.0, ATM)
    length = line_length_for_height(sol, 0, 300.0)
    assert 300.0 / np.sin(np.radians(60)) < length < 300.0 / np.sin(np.radians(50))
    assert sol.position(0, round(length)).height_m == pytest.approx(300.0, abs=1.0)
    assert np.isnan(line_length_for_height(sol, 0, 2000.0))


def test_bad_arguments():
    with pytest.raises(ValueError):
        solve_line(DYNEEMA, KITE, [0.0], 100.0, ATM)
    sol = solve_line(DYNEEMA, KITE, [7.0], 100.0, ATM)
    with pytest.raises(ValueError, match="beyond"):
        sol.position(0, 200.0)
