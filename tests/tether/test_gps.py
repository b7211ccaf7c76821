"""Flight angles from GPS logs: constructed logs, file formats, bad inputs, synthetic logs."""

import numpy as np
import pandas as pd
import pytest
from pyproj import Transformer

from kitegully import InputError
from kitegully.seeds import rng_for
from kitegully.tether.gps import (
    LineSchedule,
    SyntheticFlight,
    SyntheticLogSettings,
    flight_angles,
    read_track,
    simulate_flight_logs,
    summarise_flight_angles,
    write_gpx,
)
from kitegully.tether.line import Atmosphere, Kite, LineMaterial, kite_position

CRS = "EPSG:32632"
X0, Y0 = 578800.0, 4081500.0


def _track(times, x, y, z):
    return pd.DataFrame({"time": pd.to_datetime(times, utc=True), "x": x, "y": y, "z": z})


def test_flight_angle_on_a_constructed_log():
    t = pd.date_range("2013-09-10T08:00:00Z", periods=120, freq="1s")
    op = _track(t, np.full(120, X0), np.full(120, Y0), np.full(120, 100.0))
    # camera 3-4-5 triangle: 60 m east, 80 m north (100 m away), 100 m up -> 45°
    cam = _track(t, np.full(120, X0 + 60), np.full(120, Y0 + 80), np.full(120, 200.0))
    sched = LineSchedule((0.0, 60.0), (150.0, 300.0), settle_s=10.0)
    out = flight_angles(cam, op, sched)
    np.testing.assert_allclose(out["flight_angle_deg"], 45.0)
    np.testing.assert_allclose(out["horizontal_distance_m"], 100.0)
    # 120 pairs minus the 10 s settling after the change at 60 s
    assert len(out) == 110
    assert set(out["line_length_m"]) == {150.0, 300.0}


def test_logs_pair_only_on_common_seconds():
    t = pd.date_range("2013-09-10T08:00:00Z", periods=10, freq="1s")
    op = _track(t, np.full(10, X0), np.full(10, Y0), np.zeros(10))
    cam = _track(t + pd.Timedelta(hours=1), np.full(10, X0 + 1), np.full(10, Y0), np.ones(10))
    with pytest.raises(InputError, match="share no timestamp"):
        flight_angles(cam, op, LineSchedule((0.0,), (100.0,)))


def test_gpx_round_trip_and_csv_forms(tmp_path):
    t = pd.date_range("2013-09-10T08:00:00Z", periods=5, freq="1s")
    track = _track(t, X0 + np.arange(5.0), np.full(5, Y0), 100 + np.arange(5.0))
    write_gpx(track, tmp_path / "a.gpx", CRS, "test")
    back = read_track(tmp_path / "a.gpx", CRS)
    np.testing.assert_allclose(back["x"], track["x"], atol=0.01)  # 1e-8 deg ~ 1 mm
    np.testing.assert_allclose(back["z"], track["z"], atol=0.005)
    assert (back["time"] == track["time"]).all()
    # CSV in WGS84
    lon, lat = Transformer.from_crs(CRS, "EPSG:4326", always_xy=True).transform(track["x"], track["y"])
    pd.DataFrame({"time": t.strftime("%Y-%m-%dT%H:%M:%SZ"), "lat": lat, "lon": lon, "ele": track["z"]}).to_csv(
        tmp_path / "b.csv", index=False
    )
    np.testing.assert_allclose(read_track(tmp_path / "b.csv", CRS)["y"], track["y"], atol=1e-3)
    # CSV in the site CRS
    track.assign(time=t.strftime("%Y-%m-%dT%H:%M:%SZ")).to_csv(tmp_path / "c.csv", index=False)
    np.testing.assert_allclose(read_track(tmp_path / "c.csv", CRS)["x"], track["x"])


@pytest.mark.parametrize(
    "content, message",
    [
        ("time,a,b\n2013-09-10T08:00:00Z,1,2\n", "needs columns"),
        ("x,y,z\n1,2,3\n", "no 'time' column"),
        ("time,x,y,z\nyesterday,1,2,3\n", "cannot parse"),
        ("time,x,y,z\n2013-09-10T08:00:00Z,1,2,3\n2013-09-10T08:00:00Z,1,2,3\n", "share one second"),
    ],
)
def test_bad_csv_logs_name_the_file(tmp_path, content, message):
    p = tmp_path / "log.csv"
    p.write_text(content)
    with pytest.raises(InputError, match=message) as err:
        read_track(p, CRS)
    assert str(p) in str(err.value)


def test_bad_gpx(tmp_path):
    p = tmp_path / "broken.gpx"
    p.write_text("<gpx><trk><trkseg><trkpt lat='1' lon='2'>")
    with pytest.raises(InputError, match="not a valid GPX"):
        read_track(p, CRS)
    with pytest.raises(InputError, match="not found"):
        read_track(tmp_path / "missing.gpx", CRS)


def test_synthetic_logs_recover_the_model_angle_within_gps_noise():
    kite = Kite("delta10", 8.7, 0.15, 60.0, 2.7, 0.5)
    line = LineMaterial("dyneema", 0.8e-3, 0.39e-3, 870.0)
    sched = LineSchedule((0.0, 400.0), (150.0, 600.0), settle_s=30.0)
    flight = SyntheticFlight("T", kite, line, 8.0, 0.0, 20.0, sched, 800, "2013-09-10T08:00:00Z")
    sd = 3.0
    settings = SyntheticLogSettings(X0, Y0, 100.0, 45.0, 135.0, 0.3, 0.0, sd, sd)
    atm = Atmosphere()
    cam, op = simulate_flight_logs(flight, settings, atm, rng_for(1, "t"))
    again, _ = simulate_flight_logs(flight, settings, atm, rng_for(1, "t"))
    pd.testing.assert_frame_equal(cam, again)
    angles = flight_angles(cam, op, sched)
    angles["flight"], angles["kite"] = "T", "delta10"
    summary = summarise_flight_angles(angles)
    for row in summary.itertuples():
        truth = kite_position(line, kite, 8.0, row.line_length_m, atm)
        # Median of ~370 fixes; each angle error ~ noise / line length (rad) -> tolerance 0.5 of that
        tol = np.degrees(0.5 * np.sqrt(2) * sd / row.line_length_m)
        assert row.median_deg == pytest.approx(truth.flight_angle_deg, abs=tol)
        # the spread of single fixes reflects GPS noise: larger on the short line
    spread = summary.set_index("line_length_m")
    assert (spread.loc[150, "p95_deg"] - spread.loc[150, "p05_deg"]) > (spread.loc[600, "p95_deg"] - spread.loc[600, "p05_deg"])


def test_unmodelled_effects_move_the_camera_off_the_model():
    """Kite lag, pendulum swing and walking-speed changes (issue 15) make the logs differ from the model."""
    kite = Kite("delta10", 8.7, 0.15, 60.0, 2.7, 0.5)
    line = LineMaterial("dyneema", 0.8e-3, 0.39e-3, 870.0)
    sched = LineSchedule((0.0,), (300.0,), settle_s=30.0)
    flight = SyntheticFlight("T", kite, line, 8.0, 1.0, 20.0, sched, 600, "2013-09-10T08:00:00Z")
    atm = Atmosphere()
    base = SyntheticLogSettings(X0, Y0, 100.0, 45.0, 135.0, 0.3, 3.0, 0.0, 0.0)
    cam0, op0 = simulate_flight_logs(flight, base, atm, rng_for(2, "t"))
    swing = SyntheticLogSettings(X0, Y0, 100.0, 45.0, 135.0, 0.3, 3.0, 0.0, 0.0, pendulum_rms_deg=10.0)
    cam1, _ = simulate_flight_logs(flight, swing, atm, rng_for(2, "t"))
    # same wind draw, so the only difference is the swing: RMS offset about L sin(10 deg) per axis
    dxy = np.hypot(cam1["x"] - cam0["x"], cam1["y"] - cam0["y"])
    assert 0.5 * 3.0 * np.sin(np.radians(10)) < float(np.sqrt(np.mean(dxy**2))) < 3 * 3.0 * np.sin(np.radians(10))
    walk = SyntheticLogSettings(X0, Y0, 100.0, 45.0, 135.0, 0.3, 3.0, 0.0, 0.0, walking_speed_sd_m_s=0.3)
    _, op2 = simulate_flight_logs(flight, walk, atm, rng_for(2, "t"))
    step = np.hypot(np.diff(op2["x"]), np.diff(op2["y"]))
    assert step.std() > 0.1 and step.min() >= 0.0 and np.hypot(np.diff(op0["x"]), np.diff(op0["y"])).std() < 1e-9
    lag = SyntheticLogSettings(X0, Y0, 100.0, 45.0, 135.0, 0.3, 3.0, 0.0, 0.0, kite_response_s=5.0)
    cam3, _ = simulate_flight_logs(flight, lag, atm, rng_for(2, "t"))
    # the lag smooths the gust response: smaller second-to-second height changes
    assert np.diff(cam3["z"]).std() < np.diff(cam0["z"]).std()
