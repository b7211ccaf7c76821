"""The full-size Kamech site (issue 21) holds the paper's extent and acquisition (Table 2)."""

from pathlib import Path

from kitegully.config import load_yaml, validate_config
from kitegully.terrain.tiling import TilingParams

REPO = Path(__file__).resolve().parents[1]
SITE = REPO / "config/sites/kamech_full.yaml"


def test_kamech_full_is_the_paper_survey():
    cfg = validate_config({**load_yaml(REPO / "config/config.yaml"), **load_yaml(SITE)},
                          [REPO / "config/config.yaml", SITE])
    ext = cfg["twin"]["extent"]
    assert abs(ext["width_m"] * ext["height_m"] / 1e6 - 3.18) < 0.005
    assert cfg["flight"]["line_lengths_m"] == [150, 360, 600]
    assert cfg["twin"]["targets"]["count"] == 8
    assert cfg["twin"]["survey"]["checkpoints"]["count"] == 469
    assert cfg["dense"]["cell_m"] == 0.2
    # every stage of the default twin, epoch 2 and the change stage included
    default = load_yaml(REPO / "config/sites/kamech_twin.yaml")
    assert set(default) <= set(cfg)
    assert "epoch2" in cfg["twin"] and "change" in cfg and "polygons" in cfg and cfg["obia"]["kite_scale"]["enabled"]
    assert TilingParams.from_config(cfg).counts == (3, 5)


def _leaves(node: dict, path: tuple = ()) -> dict:
    """Every leaf of a nested config as {dotted path: value}."""
    out = {}
    for key, value in node.items():
        if isinstance(value, dict):
            out.update(_leaves(value, path + (key,)))
        else:
            out[".".join(path + (key,))] = value
    return out


#: What issue 21 changes on the default twin, and nothing else (the site file's header says so).
FULL_SIZE_CHANGES = {
    "site.name", "site.description",
    "twin.extent.xmin", "twin.extent.ymin", "twin.extent.width_m", "twin.extent.height_m",
    "twin.terrain.right_bank.relief_m", "twin.terrain.right_bank.width_m",
    "twin.terrain.left_bank.relief_m", "twin.terrain.left_bank.width_m",
    "twin.targets.count", "flight.line_lengths_m", "flight.forward_overlap",
    "sfm.deterministic", "dense.matching.max_views", "tiling.tile_m", "tiling.extent",
    # the block size decides them: epoch 2 has 516 photos here, enough for its own camera; and the
    # default twin's 10 000 tie points are 175 a photo there but 13-19 here (every tie point is used)
    "georef.camera_from_first_epoch", "georef.max_tie_points",
    # the change budget's variogram reaches half the site's diagonal (session 29): 360 m there, 1 300 m here
    "change.budget.variogram_max_lag_m",
}


def test_kamech_full_runs_the_default_twins_methods():
    """Only the extent and acquisition differ: a method setting changed on the default twin reaches the full site."""
    default = _leaves(load_yaml(REPO / "config/sites/kamech_twin.yaml"))
    full = _leaves(load_yaml(SITE))
    differing = {key for key in default.keys() | full.keys() if default.get(key, "absent") != full.get(key, "absent")}
    assert differing - FULL_SIZE_CHANGES == set()
