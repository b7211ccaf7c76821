"""The survey-design variant of the default twin (config/sites/variants/kamech_twin_gsd7cm.yaml)
changes the photographs' resolution and what follows from it, and nothing else."""

from __future__ import annotations

from pathlib import Path

import pytest

from kitegully.config import load_yaml, merge_config, validate_config

ROOT = Path(__file__).resolve().parents[2]
BASE, GSD7 = ROOT / "config/sites/kamech_twin.yaml", ROOT / "config/sites/variants/kamech_twin_gsd7cm.yaml"


@pytest.fixture(scope="module")
def configs() -> tuple[dict, dict]:
    base = load_yaml(BASE)
    cfg = merge_config(load_yaml(BASE), load_yaml(GSD7))
    validate_config(merge_config(load_yaml(ROOT / "config/config.yaml"), cfg), sources=[BASE, GSD7])
    return base, cfg


def test_same_ground_flights_and_survey(configs):
    base, cfg = configs
    for section in ("twin", "seed", "tether", "polygons", "obia"):
        assert cfg[section] == base[section], section
    flight = {k: v for k, v in cfg["flight"].items() if k not in ("camera", "gcps")}
    assert flight == {k: v for k, v in base["flight"].items() if k not in ("camera", "gcps")}
    cam, cam0 = cfg["flight"]["camera"], base["flight"]["camera"]
    # the same sensor and lens: the footprint, hence the flight plan and overlaps, are unchanged
    for key in ("sensor_width_mm", "sensor_height_mm", "focal_length_mm", "k1", "k2"):
        assert cam[key] == cam0[key]


def test_pixel_and_cell_halved_windows_follow(configs):
    base, cfg = configs
    cam, cam0 = cfg["flight"]["camera"], base["flight"]["camera"]
    assert cam["image_width_px"] == 2 * cam0["image_width_px"]
    assert cam["image_height_px"] == pytest.approx(2 * cam0["image_height_px"], abs=1)
    assert cam["principal_point_offset_px"] == [2 * v for v in cam0["principal_point_offset_px"]]
    d, d0 = cfg["dense"], base["dense"]
    assert d["cell_m"] == d0["cell_m"] / 2
    # the coarsest search level and the tile keep their size in metres
    assert d["cell_m"] * 2 ** (d["matching"]["levels"] - 1) == d0["cell_m"] * 2 ** (d0["matching"]["levels"] - 1)
    assert d["tile_cells"] * d["cell_m"] == d0["tile_cells"] * d0["cell_m"]
    assert d["overlap_cells"] % 2 ** (d["matching"]["levels"] - 1) == 0
    window = (2 * d["matching"]["window_half_cells"] + 1) * d["cell_m"]
    window0 = (2 * d0["matching"]["window_half_cells"] + 1) * d0["cell_m"]
    assert window == pytest.approx(window0 / 2)
    # every parameter stated as "the matching window" follows it
    assert cfg["change"]["headcuts"]["window_m"] == pytest.approx(window)
    assert cfg["gully"]["crowns"]["window_m"] == pytest.approx(window)
    assert cfg["gully"]["automatic_heads"]["slope_window_m"] == pytest.approx(window)
    assert cfg["gully"]["trace_smoothing_m"] == pytest.approx(window / 2)
    assert cfg["change"]["widening"]["end_m"] == pytest.approx(window)
    assert cfg["change"]["quality"]["void_margin_m"] == pytest.approx(d["matching"]["window_half_cells"] * d["cell_m"])
    assert cfg["site"]["name"] == "kamech_twin_gsd7cm"
