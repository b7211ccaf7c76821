"""benchmarks/draw_holdout_twins.py: the held-out twins are drawn, not picked, inside the ensemble's range."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "benchmarks"))

import draw_holdout_twins as dh  # noqa: E402


def test_the_committed_files_are_the_draw_of_their_seed(tmp_path):
    # rerunning the stated command writes the same files: nobody edited a drawn twin afterwards
    for seed, names in ((20261206, ("h3", "h4", "h5", "h6")), (20261207, ("h7", "h8", "h9", "h10")),
                        (20261208, ("h11", "h12", "h13", "h14")), (20261209, ("h15", "h16", "h17", "h18")),
                        (20261210, ("h19", "h20", "h21", "h22")), (20261208, ("h23", "h24", "h25", "h26"))):
        rng = np.random.default_rng(seed)
        for name in names:
            text = dh.site_file(name, 1000 + 101 * int(name[1:]), dh.draw(rng), seed)
            assert text == (REPO / "config" / "sites" / "holdout" / f"{name}.yaml").read_text()


def test_draws_stay_inside_the_ensemble_range():
    ens = [yaml.safe_load(p.read_text()) for p in sorted((REPO / "config" / "sites" / "ensemble").glob("*.yaml"))]
    lo = {"g": min(e["twin"]["texture"]["grass_greenness"] for e in ens),
          "s": min(e["twin"]["texture"]["illumination"]["sun_elevation_deg"] for e in ens),
          "tg": min(e["twin"]["landcover"]["shrubs"]["threshold_gully"] for e in ens),
          "sh": min(e["twin"]["gullies"]["shallow_share_left"] for e in ens),
          "d": min(e["twin"]["survey"]["heads_sigma_m"] for e in ens)}
    hi = {"g": max(e["twin"]["texture"]["grass_greenness"] for e in ens),
          "s": max(e["twin"]["texture"]["illumination"]["sun_elevation_deg"] for e in ens),
          "tg": max(e["twin"]["landcover"]["shrubs"]["threshold_gully"] for e in ens),
          "sh": max(e["twin"]["gullies"]["shallow_share_left"] for e in ens),
          "d": max(e["twin"]["survey"]["heads_sigma_m"] for e in ens)}
    rng = np.random.default_rng(0)
    for _ in range(200):
        p = dh.draw(rng)
        for key, v in (("g", p["greenness"]), ("s", p["sun_deg"]), ("tg", p["threshold_gully"]),
                       ("sh", p["shallow"]), ("d", p["heads_sigma_m"])):
            assert lo[key] - 1e-9 <= v <= hi[key] + 1e-9


@pytest.mark.parametrize("seed, names, greenness, shrub_u", [(20261211, ("h27", "h28", "h29"), (0.4, 0.7), (0.8, 1.0)),
                                                          (20261212, ("h30", "h31", "h32"), (0.5, 0.6), (0.85, 1.0))])
def test_a_stress_set_is_drawn_in_its_declared_part_of_the_range_and_says_so(seed, names, greenness, shrub_u):
    rng = np.random.default_rng(seed)
    flags = f"--greenness {greenness[0]},{greenness[1]} --shrub-u {shrub_u[0]},{shrub_u[1]}"  # as typed
    for name in names:
        p = dh.draw(rng, greenness_range=greenness, shrub_range=shrub_u)
        assert greenness[0] <= p["greenness"] <= greenness[1] and shrub_u[0] <= p["shrub_u"] <= shrub_u[1]
        text = dh.site_file(name, 1000 + 101 * int(name[1:]), p, seed, flags)
        assert text == (REPO / "config" / "sites" / "holdout" / f"{name}.yaml").read_text()
        assert "a declared part of the ensemble's range" in text and "stress draw" in text
