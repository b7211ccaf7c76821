"""Second survey of the twin (issue 17): targets lost/moved between campaigns, the epoch-2 sun,
and per-epoch random streams that leave epoch 1's numbers unchanged."""

from __future__ import annotations

import zlib

import numpy as np
import pandas as pd
import pytest

from kitegully import InputError
from kitegully.io.raster import GridSpec
from kitegully.seeds import epoch_rng, epoch_seed
from kitegully.twin.epochs import disturb_targets, texture_config
from kitegully.twin.landcover import CODE


def _targets(n=8):
    return pd.DataFrame({"gcp_id": [f"GCP{i}" for i in range(n)], "x": 20.0 + 10.0 * np.arange(n),
                         "y": np.full(n, -50.0), "z": np.zeros(n), "size_m": 1.0})


def _lc():
    grid = GridSpec(0.0, 0.0, 0.5, 240, 200, "EPSG:32632")
    lc = np.full((grid.height, grid.width), CODE["ploughed"], dtype=np.uint8)
    lc[:, :60] = CODE["tree"]  # no open ground around x < 30 m
    return lc, grid


def test_lost_and_moved_targets():
    lc, grid = _lc()
    t = _targets()
    cfg = {"targets_lost": 2, "targets_moved": 2, "target_move_m": [2.0, 5.0]}
    out, fate = disturb_targets(t, cfg, 7, lc, grid, ["ploughed", "grass"])
    assert len(out) == len(t) - 2
    lost = set(fate.loc[fate["fate"] == "lost", "gcp_id"])
    assert len(lost) == 2 and not lost & set(out["gcp_id"])
    moved = fate[fate["fate"] == "moved"]
    d = np.hypot(moved["dx_m"], moved["dy_m"])
    assert ((d >= 2.0) & (d <= 5.0)).all()
    for _, m in moved.iterrows():  # moved targets lie on open ground, where the survey puts them
        row = out.set_index("gcp_id").loc[m["gcp_id"]]
        r, c = (int(v) for v in np.round(grid.rowcol(row["x"], row["y"])))
        assert lc[r, c] == CODE["ploughed"]
    # reproducible, and nothing changes without the keys
    out2, _ = disturb_targets(t, cfg, 7, lc, grid, ["ploughed"])
    pd.testing.assert_frame_equal(out, out2)
    same, none = disturb_targets(t, {}, 7, lc, grid, ["ploughed"])
    pd.testing.assert_frame_equal(same, t)
    assert none.empty


def test_too_many_disturbed_targets_is_one_sentence():
    lc, grid = _lc()
    with pytest.raises(InputError, match=r"twin.epoch2: targets_lost \+ targets_moved \(6\) must leave at least 4"):
        disturb_targets(_targets(8), {"targets_lost": 3, "targets_moved": 3}, 7, lc, grid, ["ploughed"])


def test_epoch2_sun_overlay():
    tex = {"palette": {}, "illumination": {"gain": 1.0, "sun_azimuth_deg": 135.0, "sun_elevation_deg": 50.0}}
    new = texture_config(tex, {"illumination": {"sun_azimuth_deg": 110.0}})
    assert new["illumination"] == {"gain": 1.0, "sun_azimuth_deg": 110.0, "sun_elevation_deg": 50.0}
    assert tex["illumination"]["sun_azimuth_deg"] == 135.0
    assert texture_config(tex, None) is tex


def test_epoch1_streams_unchanged_epoch2_independent():
    old = np.random.default_rng([2018, zlib.crc32(b"flight.simulate")]).random(5)
    np.testing.assert_array_equal(epoch_rng(2018, 1, "flight", "simulate").random(5), old)
    assert epoch_seed(2018, 1, "flight", "render") == zlib.crc32(b"flight.render") ^ 2018
    assert not np.allclose(epoch_rng(2018, 2, "flight", "simulate").random(5), old)
    assert epoch_seed(2018, 2, "flight", "render") == epoch_seed(2018, 2, "flight", "render")
    assert epoch_seed(2018, 2, "flight", "render") != epoch_seed(2018, 1, "flight", "render")


def test_retreated_head_keeps_its_vertex_spacing():
    """A 2.5 m retreat on a gully traced every 1 m adds 3 vertices (0.83 m apart), not one 2.5 m wedge."""
    from kitegully.twin.epochs import retreat_heads
    from kitegully.twin.gullies import Gully

    head = Gully(1, "gully", "right", "V", np.arange(0.0, 11.0), np.zeros(11), headcut=True, joins=0)
    side = Gully(2, "gully", "right", "V", np.array([5.0, 5.0]), np.array([8.0, 1.0]), headcut=False, joins=1, join_index=5)
    got = retreat_heads([head, side], {"headcut_retreat_m": [2.5, 2.5]}, seed=0)
    assert got == {1: 2.5}
    np.testing.assert_allclose(head.x[:5], [-2.5, -2.5 + 2.5 / 3, -2.5 + 5 / 3, 0.0, 1.0])
    assert np.max(np.diff(head.x)) <= 1.0 + 1e-12 and np.all(head.y == 0)
    assert head.x[side.join_index] == 5.0  # the tributary still joins at the same point
    assert len(side.x) == 2  # no headcut, no retreat
