"""The tether stage's products (kitegully.tether.stage) on the tiny site's tether section."""

from __future__ import annotations

import numpy as np
import pytest

from kitegully.config import load_yaml
from kitegully.tether.analysis import flight_angle_table
from kitegully.tether.config import atmosphere_from_config, kites_from_config, materials_from_config, sweep_lengths
from kitegully import InputError
from kitegully.tether.stage import PLAN_KEYS, SIMULATION_KEYS, TetherParams, plan_flights, simulate_tether
from snakemake_utils import REPO

TETHER = load_yaml(REPO / "config" / "sites" / "tiny_twin.yaml")["tether"]


def _keys(keys):
    return {k: TETHER[k] for k in keys}


def test_simulate_tether_reads_only_its_keys_and_matches_the_table():
    cfg = _keys(SIMULATION_KEYS)  # a KeyError here means the rule's params miss a key
    sim = simulate_tether(TetherParams.from_config(cfg))
    expected = flight_angle_table(
        materials_from_config(cfg), kites_from_config(cfg)[cfg["simulation_kite"]], cfg["sweep"]["winds_m_s"],
        sweep_lengths(cfg), atmosphere_from_config(cfg), cfg["segment_length_m"],
    )
    assert sim.table.equals(expected)
    assert cfg["reference_line"] not in sim.solutions
    assert set(sim.solutions) == set(cfg["lines"]) - {cfg["reference_line"]}
    c = sim.comparison
    assert set(c["reading"]) == {"bridle_tension [I-A]", "aero_resultant [I-B]"}
    assert (c["within_tolerance"] == (c["difference_pct"].abs() <= cfg["table2"]["tolerance_pct"])).all()


def test_plan_flights_reads_only_its_keys():
    plan, lengths = plan_flights(TetherParams.from_config(_keys(PLAN_KEYS)))
    assert list(plan["flying_height_m"]) == pytest.approx(TETHER["plan"]["flying_heights_m"])
    assert set(lengths["flying_height_m"]) == set(plan["flying_height_m"])
    assert set(lengths["material"]) == set(TETHER["lines"])
    assert set(lengths["wind_m_s"]) == set(TETHER["sweep"]["winds_m_s"])
    # a reachable height needs a line at least as long as the height
    ok = lengths[lengths["reachable"]]
    assert np.all(ok["line_length_m"] >= ok["flying_height_m"])


def test_synthetic_logs_give_back_their_flight_angles(tmp_path):
    from kitegully.tether.gps import write_gpx
    from kitegully.tether.stage import observed_flight_angles, synthetic_gps_logs

    cfg = _keys(("lines", "kites", "kite_model", "atmosphere", "segment_length_m", "observed", "simulation_kite", "sweep"))
    crs = load_yaml(REPO / "config" / "sites" / "tiny_twin.yaml")["site"]["crs"]
    params = TetherParams.from_config(cfg)
    logs = synthetic_gps_logs(params, seed=3)
    again = synthetic_gps_logs(params, seed=3)
    assert [n for n, _, _ in logs] == [f["name"] for f in cfg["observed"]["flights"]]
    assert all(a[1].equals(b[1]) for a, b in zip(logs, again))
    cams, ops = [], []
    for name, cam, op in logs:
        cams.append(tmp_path / f"{name}_camera.gpx")
        ops.append(tmp_path / f"{name}_operator.gpx")
        write_gpx(cam, cams[-1], crs, name)
        write_gpx(op, ops[-1], crs, name)
    res = observed_flight_angles(params, cams, ops, crs)
    assert set(res.fixes["flight"]) == set(res.summary["flight"]) == {n for n, _, _ in logs}
    assert res.fixes["time"].str.endswith("Z").all()
    assert res.fixes["flight_angle_deg"].between(0, 90).all()
    assert res.simulated is not None and set(res.simulated["wind_m_s"]) == {
        f["wind_m_s"] for f in cfg["observed"]["flights"] if "wind_m_s" in f
    }


def test_tether_params_name_a_missing_or_unknown_key():
    cfg = _keys(SIMULATION_KEYS)
    del cfg["atmosphere"]
    with pytest.raises(InputError, match="tether: missing key 'atmosphere'"):
        TetherParams.from_config(cfg)
    with pytest.raises(InputError, match="unknown key 'windz'"):
        TetherParams.from_config({**_keys(SIMULATION_KEYS), "windz": 1})
    with pytest.raises(InputError, match="tether.simulation_kite: unknown kite 'nope'"):
        TetherParams.from_config({**_keys(SIMULATION_KEYS), "simulation_kite": "nope"})
