"""Thresholds remove noise-only cells at the stated rate; sigma propagation; checkpoint sigma."""

import numpy as np
import pandas as pd
import pytest
from change.change_synth import grid, noise, terrain, write, xy
from scipy import stats

from kitegully.change.dod import load_epoch
from kitegully.change.params import ChangeParams
from kitegully.change.uncertainty import detect, epoch_sigma, propagate, thresholded, z_of_confidence

SD = 0.05


def _noise_dod(n=400):
    g = grid(n)
    dod = (noise(g, SD, "a") - noise(g, SD, "b")).astype(np.float32)
    return g, dod, propagate(SD, SD, dod.shape)


def test_propagated_sigma():
    s = propagate(0.03, np.full((2, 2), 0.04), (2, 2))
    assert np.allclose(s, 0.05)
    assert z_of_confidence(0.95) == pytest.approx(1.96, abs=0.001)


@pytest.mark.parametrize("method, expected", [
    ("probabilistic", 0.05),                                           # 95 %: 5 % of noise survives
    ("propagated", 2 * stats.norm.sf(1.0)),                            # t = 1: 31.7 %
    ("min_lod", 2 * stats.norm.sf(0.1 / (SD * np.sqrt(2)))),           # |DoD| > 0.1 m
])
def test_noise_only_cells_kept_at_stated_rate(method, expected):
    _, dod, sigma = _noise_dod()
    kept = detect(dod, sigma, ChangeParams(min_lod_m=0.1))[method].mean()
    assert kept == pytest.approx(expected, abs=0.005)


def test_coherence_keeps_coherent_weak_change_and_little_noise():
    g, dod, sigma = _noise_dod(200)
    block = np.zeros(dod.shape, bool)
    block[50:90, 50:90] = True
    dod = np.where(block, dod - 0.12, dod).astype(np.float32)  # |t| ≈ 1.7 < 1.96: weak, but coherent
    det = detect(dod, sigma, ChangeParams())
    assert det["coherence"][block].mean() > det["probabilistic"][block].mean() + 0.2
    assert det["coherence"][~block].mean() < 0.07  # noise alone is not coherent: about the 5 % of (c)
    th = thresholded(dod, det["probabilistic"])
    assert (th[~det["probabilistic"]] == 0).all() and np.isnan(thresholded(np.array([np.nan]), np.array([True]))).all()


def test_sigma_from_checkpoints(tmp_path):
    g = grid(100)
    X, Y = xy(g)
    z = terrain(X, Y)
    rng = np.random.default_rng(3)
    err = rng.normal(0.02, 0.07, (g.height, g.width))
    dem = write(tmp_path / "d.tif", z + err, g)
    r, c = rng.integers(5, 95, 300), rng.integers(5, 95, 300)
    cp = pd.DataFrame(dict(id=range(300), x=X[r, c], y=Y[r, c], z=z[r, c]))
    cp.to_csv(tmp_path / "cp.csv", index=False)
    e = load_epoch({"name": "e1", "dem": dem, "accuracy": {"checkpoints": str(tmp_path / "cp.csv")}}, "k")
    s, info = epoch_sigma(e, g)
    assert s == pytest.approx(0.07, rel=0.15)
    assert info["n"] == 300 and info["mean_m"] == pytest.approx(0.02, abs=0.015)
    e2 = load_epoch({"name": "e2", "dem": dem, "accuracy": {"rmse_m": 0.1}}, "k")
    assert epoch_sigma(e2, g)[0] == 0.1


def test_checkpoint_blunders_are_counted_not_averaged_into_sigma(tmp_path):
    """Two gross matching errors (metres) among 300 checkpoints of 0.05 m noise: sigma stays the noise's SD."""
    g = grid(100)
    X, Y = xy(g)
    z = terrain(X, Y)
    rng = np.random.default_rng(5)
    zd = z + rng.normal(0.0, 0.05, (g.height, g.width))
    r, c = rng.integers(5, 95, 300), rng.integers(5, 95, 300)
    zd[r[0], c[0]] -= 9.7  # a mismatch at one checkpoint, as on an ensemble twin's epoch 2
    zd[r[1], c[1]] += 1.1
    dem = write(tmp_path / "d.tif", zd, g)
    pd.DataFrame(dict(id=range(300), x=X[r, c], y=Y[r, c], z=z[r, c])).to_csv(tmp_path / "cp.csv", index=False)
    e = load_epoch({"name": "e1", "dem": dem, "accuracy": {"checkpoints": str(tmp_path / "cp.csv")}}, "k")
    s, info = epoch_sigma(e, g)
    assert s == pytest.approx(0.05, rel=0.15)
    assert info["blunders"] == 2 and info["n"] == 298 and "2 blunders" in info["source"]
    assert info["sd_all_m"] > 0.5
    s_all, info_all = epoch_sigma(e, g, outlier_nmad=None)
    assert s_all == pytest.approx(info["sd_all_m"]) and info_all["blunders"] == 0
    with pytest.raises(Exception, match="checkpoint_outlier_nmad"):
        ChangeParams(checkpoint_outlier_nmad=0.0)
