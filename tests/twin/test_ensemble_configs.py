"""The ensemble site files (config/sites/ensemble/) validate on top of the default site."""

from __future__ import annotations

from pathlib import Path

import pytest

from kitegully.config import load_yaml, validate_config

REPO = Path(__file__).resolve().parents[2]
FILES = sorted((REPO / "config/sites/ensemble").glob("*.yaml"))


def _merge(a, b):
    out = dict(a)
    for k, v in b.items():
        out[k] = _merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


def test_five_members_with_distinct_names_and_seeds():
    assert len(FILES) == 5
    cfgs = [load_yaml(f) for f in FILES]
    assert len({c["site"]["name"] for c in cfgs}) == 5
    assert len({c["seed"] for c in cfgs} | {load_yaml(REPO / "config/sites/kamech_twin.yaml")["seed"]}) == 6


@pytest.mark.parametrize("path", FILES, ids=[f.stem for f in FILES])
def test_member_validates_and_snap_radius_follows_the_digitising_error(path):
    base = _merge(load_yaml(REPO / "config/config.yaml"), load_yaml(REPO / "config/sites/kamech_twin.yaml"))
    cfg = validate_config(_merge(base, load_yaml(path)))
    assert cfg["gully"]["head_snap_radius_m"] == pytest.approx(3 * cfg["twin"]["survey"]["heads_sigma_m"])
    assert 2.0 <= cfg["twin"]["survey"]["heads_sigma_m"] <= 4.0
    assert 25 <= cfg["twin"]["texture"]["illumination"]["sun_elevation_deg"] <= 60
