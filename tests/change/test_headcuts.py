"""Headcut retreat of a synthetic channel whose head moves upslope by a known distance."""

import numpy as np
import pandas as pd
import pytest
from change.change_synth import grid, noise, xy

from kitegully.change.headcuts import measure_headcut_retreat
from kitegully.change.params import ChangeParams


def _channel(g, head_x):
    """Slope falling to the east (x); a 1 m deep, 3 m wide V channel from head_x downslope."""
    X, Y = xy(g)
    x, y = X - g.x0, g.y0 - Y
    z = 100.0 - 0.08 * x
    across = np.abs(y - 50.0)
    depth = np.clip(1.0 - across / 1.5, 0, None) * np.clip((x - head_x) / 0.6, 0, 1)
    return (z - depth).astype(np.float32)


@pytest.mark.parametrize("retreat", [0.0, 1.0, 2.5])
def test_retreat_measured(retreat):
    g = grid(200, cell=0.5)
    z1 = _channel(g, 40.0) + noise(g, 0.02, "h1")
    z2 = _channel(g, 40.0 - retreat) + noise(g, 0.02, "h2")
    heads = pd.DataFrame(dict(head_id=[1], x=[g.x0 + 42.0], y=[g.y0 - 51.0]))  # digitised 2 m off
    out = measure_headcut_retreat(z1, z2, g, heads, ChangeParams(headcut_search_radius_m=8.0))
    assert out["retreat_m"].iloc[0] == pytest.approx(retreat, abs=0.5)
    assert out["retreat_heads_m"].iloc[0] == pytest.approx(retreat, abs=0.5)
    assert out["retreat_heads_upslope_m"].iloc[0] == pytest.approx(retreat, abs=0.5)
    assert out["x1"].iloc[0] - g.x0 == pytest.approx(40.0, abs=0.75)
