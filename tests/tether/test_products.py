"""The tether stage's products (kitegully.tether.products) on the tiny site's tether section."""

from __future__ import annotations

import numpy as np
import pytest

from kitegully.config import load_yaml
from kitegully.tether.analysis import flight_angle_table
from kitegully.tether.config import atmosphere_from_config, kites_from_config, materials_from_config, sweep_lengths
from kitegully.tether.products import PLAN_KEYS, SIMULATION_KEYS, plan_flights, simulate_tether
from snakemake_utils import REPO

TETHER = load_yaml(REPO / "config" / "sites" / "tiny_twin.yaml")["tether"]


def _keys(keys):
    return {k: TETHER[k] for k in keys}


def test_simulate_tether_reads_only_its_keys_and_matches_the_table():
    cfg = _keys(SIMULATION_KEYS)  # a KeyError here means the rule's params miss a key
    sim = simulate_tether(cfg)
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
    plan, lengths = plan_flights(_keys(PLAN_KEYS))
    assert list(plan["flying_height_m"]) == pytest.approx(TETHER["plan"]["flying_heights_m"])
    assert set(lengths["flying_height_m"]) == set(plan["flying_height_m"])
    assert set(lengths["material"]) == set(TETHER["lines"])
    assert set(lengths["wind_m_s"]) == set(TETHER["sweep"]["winds_m_s"])
    # a reachable height needs a line at least as long as the height
    ok = lengths[lengths["reachable"]]
    assert np.all(ok["line_length_m"] >= ok["flying_height_m"])
