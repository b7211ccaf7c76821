"""benchmarks/change_stable_tracks.py: the simulated digitised tracks (inset, short pieces missed)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from kitegully.io.raster import GridSpec, Raster

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "benchmarks"))

import change_stable_tracks as cst  # noqa: E402


def test_tracks_are_drawn_inside_their_edges_and_short_pieces_missed(tmp_path):
    g = GridSpec(500000.0, 4100000.0, 0.1, 600, 400, "EPSG:32632")
    lc = np.full((400, 600), 3, np.uint8)
    lc[100:140, 50:550] = 6   # a track 4 m wide, 50 m long
    lc[300:330, 100:130] = 6  # a 3 m x 3 m piece: 4 m2 once inset, missed
    Raster(lc, g, 0).write(tmp_path / "lc.tif")
    pd.DataFrame({"code": [3, 6], "name": ["grass", "track"]}).to_csv(tmp_path / "lc.csv", index=False)
    tracks = cst.digitised_tracks(tmp_path / "lc.tif", tmp_path / "lc.csv", g.crs)
    assert len(tracks) == 1
    assert tracks.area.iloc[0] == pytest.approx((4.0 - 2 * cst.EDGE_INSET_M) * (50.0 - 2 * cst.EDGE_INSET_M), rel=0.01)
