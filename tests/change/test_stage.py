"""ChangeParams: the DEM site's change section builds; a missing or unknown key is named."""

from __future__ import annotations

import copy

import pytest

from conftest import REPO
from kitegully import InputError
from kitegully.change import ChangeParams
from kitegully.config import load_yaml

CHANGE = load_yaml(REPO / "config/sites/kamech_dem_change.yaml")["change"]


def test_site_section_builds():
    p = ChangeParams.from_config(CHANGE, seed=3)
    assert p.confidence == CHANGE["thresholds"]["confidence"] and p.coherence_window == 5 and p.seed == 3
    assert p.stable_max_object_height_m == CHANGE["coregistration"]["max_object_height_m"]


def test_bad_keys_are_named():
    bad = copy.deepcopy(CHANGE)
    del bad["thresholds"]["coherence"]["p_low"]
    with pytest.raises(InputError, match=r"change.thresholds.coherence: missing key 'p_low'"):
        ChangeParams.from_config(bad)
    bad = copy.deepcopy(CHANGE)
    bad["budget"]["variogram_range"] = 3
    with pytest.raises(InputError, match=r"change.budget: unknown key 'variogram_range'"):
        ChangeParams.from_config(bad)
    bad = copy.deepcopy(CHANGE)
    bad["thresholds"]["confidence"] = 1.5
    with pytest.raises(InputError, match=r"change.thresholds.confidence must be in \[0.5, 1\)"):
        ChangeParams.from_config(bad)


def test_quality_and_widening_sections():
    p = ChangeParams.from_config(CHANGE)
    assert p.min_correlation == 0.5 and p.void_margin_m == 0.4
    assert (p.widening_margin_m, p.widening_min_depth_m, p.widening_end_m) == (3.0, 0.25, 1.0)
    bare = {k: v for k, v in CHANGE.items() if k not in ("quality", "widening")}
    q = ChangeParams.from_config(bare)  # both optional: the dataclass defaults
    assert q.min_correlation == 0.5 and q.void_margin_m == 0.0 and q.widening_margin_m == 3.0
    assert q.checkpoint_outlier_nmad == 4.0 and q.heteroscedastic is False
    assert p.heteroscedastic is True  # the DEM site: photogrammetric DSMs with checkpoints on open ground
    off = copy.deepcopy(CHANGE)
    off["quality"]["checkpoint_outlier_nmad"] = None
    assert ChangeParams.from_config(off).checkpoint_outlier_nmad is None
    bad = copy.deepcopy(CHANGE)
    bad["quality"]["min_ncc"] = 0.3
    with pytest.raises(InputError, match=r"change.quality: unknown key 'min_ncc'"):
        ChangeParams.from_config(bad)
    bad = copy.deepcopy(CHANGE)
    bad["widening"]["margin_m"] = 0.0
    with pytest.raises(InputError, match=r"change.widening: margin_m, min_depth_m and end_m must be > 0 m"):
        ChangeParams.from_config(bad)


def test_a_variogram_whose_longest_range_reaches_the_maximum_lag_is_reported(tmp_path, caplog):
    # A DoD error correlated over some 50 m (white noise smoothed by a 10 m Gaussian), seen through a
    # variogram cut at 15 m: the fitted range stops at the bound, and the volume σ it gives is too
    # small; the stage says so. Cut at 141 m (half the diagonal) the range is found and nothing is said.
    import logging

    import numpy as np
    from scipy.ndimage import gaussian_filter

    from kitegully.change.stage import uncertainty_model
    from kitegully.io.raster import GridSpec

    grid = GridSpec(0.0, 200.0, 1.0, 200, 200, "EPSG:32632")
    rng = np.random.default_rng(0)
    field = gaussian_filter(rng.normal(0.0, 1.0, (200, 200)), 10.0)
    dod = 0.05 * field / field.std() + rng.normal(0.0, 0.01, (200, 200))
    sigma = np.full(dod.shape, 0.02)
    stable = np.ones(dod.shape, bool)
    out = {"variogram": str(tmp_path / "v.csv"), "variogram_png": str(tmp_path / "v.png")}
    for max_lag, warned in ((15.0, True), (141.0, False)):
        caplog.clear()
        params = ChangeParams(variogram_max_lag_m=max_lag, variogram_samples=1500)
        with caplog.at_level(logging.WARNING, logger="kitegully.change.stage"):
            vg, _ = uncertainty_model(dod, sigma, stable, grid, params, out)
        assert ("reached change.budget.variogram_max_lag_m" in caplog.text) is warned, vg.describe()
