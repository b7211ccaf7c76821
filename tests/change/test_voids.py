"""Cells matched below the stated correlation are voids; voids and DEM edges grow by the window margin."""

import numpy as np
import pytest
from change.change_synth import grid, pair, write

from kitegully import InputError
from kitegully.change.dod import load_epoch, matching_voids
from kitegully.change.params import ChangeParams


def _epochs(tmp_path, corr2):
    g, z1, z2, _ = pair()
    c1 = np.full(z1.shape, 0.9, np.float32)
    e1 = load_epoch({"name": "a", "dem": write(tmp_path / "a.tif", z1, g), "accuracy": {"sd_m": 0.05},
                     "correlation": write(tmp_path / "ca.tif", c1, g)}, "e[0]")
    e2 = load_epoch({"name": "b", "dem": write(tmp_path / "b.tif", z2, g), "accuracy": {"sd_m": 0.05},
                     "correlation": write(tmp_path / "cb.tif", corr2, g)}, "e[1]")
    return g, e1, e2


def test_low_correlation_cells_are_voids(tmp_path):
    g = grid()
    c2 = np.full((g.height, g.width), 0.9, np.float32)
    c2[50:60, 50:60] = 0.4
    c2[100, 100] = np.nan
    g, e1, e2 = _epochs(tmp_path, c2)
    v = matching_voids((e1, e2), g, 0.5)
    assert v.sum() == 101 and v[55, 55] and v[100, 100] and not v[49, 55]
    assert not matching_voids((e1, e2), g, None).any()
    # margin 0.5 m = 1 cell: the 10 x 10 block grows to 12 x 12 (Euclidean, diagonals 0.71 m stay out)
    vm = matching_voids((e1, e2), g, 0.5, margin_m=0.5, valid=np.ones(v.shape, bool))
    assert vm[49, 55] and vm[60, 55] and not vm[49, 49] and vm[50:60, 50:60].all()
    edge = np.ones(v.shape, bool)
    edge[:, :5] = False
    assert matching_voids((e1, e2), g, 0.5, margin_m=0.5, valid=edge)[:, 5].all()


def test_no_correlation_raster_means_no_voids_and_no_margin(tmp_path):
    g, z1, _, _ = pair()
    e = load_epoch({"name": "a", "dem": write(tmp_path / "a.tif", z1, g), "accuracy": {"sd_m": 0.05}}, "e[0]")
    valid = np.ones(z1.shape, bool)
    valid[:, :5] = False
    assert not matching_voids((e, e), g, 0.5, margin_m=1.0, valid=valid).any()


def test_bad_quality_inputs(tmp_path):
    g, z1, _, _ = pair()
    with pytest.raises(InputError, match="nope.tif: correlation raster of e\\[0\\] not found"):
        load_epoch({"name": "a", "dem": write(tmp_path / "a.tif", z1, g), "accuracy": {"sd_m": 0.05},
                    "correlation": str(tmp_path / "nope.tif")}, "e[0]")
    with pytest.raises(InputError, match="change.quality.min_correlation must be in"):
        ChangeParams(min_correlation=1.5)
    with pytest.raises(InputError, match="change.quality.void_margin_m must be >= 0"):
        ChangeParams(void_margin_m=-1.0)
