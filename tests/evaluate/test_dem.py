"""DEM validation statistics on constructed errors, and nodata handling."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from kitegully import InputError
from kitegully.evaluate.dem import (
    checkpoint_errors, error_raster, error_stats, profile_comparison, read_checkpoints,
    sample_bilinear, stats_by_class, summary_table,
)
from kitegully.io.raster import GridSpec
from kitegully.seeds import rng_for

GRID = GridSpec(500000.0, 4000100.0, 0.5, 200, 200, "EPSG:32632")


def _plane(x, y):
    return 100.0 + 0.02 * (x - 500000.0) - 0.01 * (y - 4000000.0)


def _dem():
    xs, ys = GRID.cell_centres()
    return _plane(xs[None, :], ys[:, None])


def test_bilinear_exact_on_plane_and_nodata():
    z = _dem()
    rng = rng_for(1, "test", "bilinear")
    x = rng.uniform(500000.3, 500099.7, 500)
    y = rng.uniform(4000000.3, 4000099.7, 500)
    assert np.allclose(sample_bilinear(z, GRID, x, y), _plane(x, y), atol=1e-9)
    zn = z.copy()
    zn[100, 100] = np.nan
    xc, yc = GRID.cell_centres()
    # a point next to a NaN cell centre is NaN; outside the grid is NaN
    v = sample_bilinear(zn, GRID, np.array([xc[100] + 0.1, 499000.0, xc[10]]), np.array([yc[100], yc[10], yc[10]]))
    assert np.isnan(v[0]) and np.isnan(v[1]) and np.isfinite(v[2])


def test_stats_on_constructed_errors():
    rng = rng_for(1, "test", "stats")
    e = rng.normal(0.06, 0.22, 20000)  # the paper's Table 3: +0.06 m, SD 0.22 m
    s = error_stats(np.concatenate([e, [np.nan] * 10]))
    assert s["n"] == 20000
    se = 0.22 / np.sqrt(20000)
    assert abs(s["mean"] - 0.06) < 4 * se
    assert abs(s["sd"] - 0.22) < 4 * 0.22 / np.sqrt(2 * 20000)
    assert s["rmse"] == pytest.approx(np.sqrt(s["mean"] ** 2 + s["sd"] ** 2 * (20000 - 1) / 20000), rel=1e-9)
    assert s["nmad"] == pytest.approx(0.22, rel=0.03)  # NMAD = SD for a normal law
    assert s["p05"] == pytest.approx(0.06 - 1.645 * 0.22, abs=0.01)
    assert s["p95"] == pytest.approx(0.06 + 1.645 * 0.22, abs=0.01)
    exact = error_stats(np.array([-1.0, 0.0, 1.0, 2.0]))
    assert exact["mean"] == 0.5 and exact["median"] == 0.5 and exact["rmse"] == pytest.approx(np.sqrt(1.5))
    assert exact["nmad"] == pytest.approx(1.4826)
    tab = summary_table(np.array([1.0, 2.0]))
    assert list(tab.columns) == ["statistic", "value_m"]
    assert list(tab["statistic"]) == ["mean", "median", "sd", "rmse", "nmad", "p05", "p95", "n"]
    assert error_stats(np.array([np.nan]))["n"] == 0


def test_checkpoint_errors_with_known_offset(tmp_path):
    z = _dem() + 0.1  # a model 0.1 m too high
    z[:20, :] = np.nan  # a nodata band in the north
    rng = rng_for(1, "test", "cp")
    x = rng.uniform(500001, 500099, 100)
    y = rng.uniform(4000001, 4000099, 100)
    p = tmp_path / "cp.csv"
    pd.DataFrame({"id": np.arange(100), "x": x, "y": y, "z": _plane(x, y)}).to_csv(p, index=False)
    df = checkpoint_errors(z, GRID, read_checkpoints(p))
    north = y > GRID.y0 - 20.5 * GRID.cell
    assert df["error_m"][north].isna().all()
    assert np.allclose(df["error_m"][~north], 0.1)
    assert error_stats(df["error_m"].to_numpy())["n"] == (~north).sum()


def test_bad_checkpoint_files(tmp_path):
    p = tmp_path / "cp.csv"
    p.write_text("id,x,y\n1,2,3\n")
    with pytest.raises(InputError, match="cp.csv.*z"):
        read_checkpoints(p)
    p.write_text("id,x,y,z\n1,2,abc,4\n")
    with pytest.raises(InputError, match="non-numeric"):
        read_checkpoints(p)
    with pytest.raises(InputError, match="cannot read"):
        read_checkpoints(tmp_path / "missing.csv")


def test_error_raster_and_classes():
    ref = _dem()
    model = ref + np.where(np.arange(200)[None, :] < 100, 0.05, 0.5)  # west bare +5 cm, east shrubs +50 cm
    cls = np.where(np.arange(200)[None, :] < 100, 1, 4).repeat(200, axis=0).astype(np.uint8)
    err = error_raster(model, GRID, ref, GRID)
    tab = stats_by_class(err, cls, {1: "bare_eroded", 4: "shrub", 7: "building"})
    by = tab.set_index("landcover")
    assert by.loc["bare_eroded", "mean_m"] == pytest.approx(0.05) and by.loc["shrub", "mean_m"] == pytest.approx(0.5)
    assert "building" not in by.index and by.loc["all", "n"] == 40000
    # a coarser reference is resampled onto the model grid
    coarse = GridSpec(GRID.x0, GRID.y0, 1.0, 100, 100, GRID.crs)
    xs, ys = coarse.cell_centres()
    e2 = error_raster(ref, GRID, _plane(xs[None, :], ys[:, None]), coarse)
    # exact inside; the outer half coarse cell is held at the edge value (no extrapolation)
    assert np.nanmax(np.abs(e2[1:-1, 1:-1])) < 1e-4  # float32 output near 100 m
    with pytest.raises(InputError, match="CRS"):
        error_raster(model, GRID, ref, GridSpec(GRID.x0, GRID.y0, 0.5, 200, 200, "EPSG:4326"))


def test_profile_with_and_without_vegetation():
    ref = _dem()
    model = ref.copy()
    model[:, 100:110] += 2.0  # a 5 m wide hedge of 2 m on the model
    cls = np.zeros(ref.shape, np.uint8)
    cls[:, 100:110] = 5
    line = [[500010.0, 4000050.0], [500090.0, 4000050.0]]
    prof, tab = profile_comparison(model, GRID, ref, GRID, line, 0.5, cls, GRID, vegetation_codes=[5])
    assert len(prof) == 161 and prof["vegetation"].sum() > 0
    t = tab.set_index("profile")
    assert t.loc["whole", "max_m"] == pytest.approx(2.0)
    assert t.loc["no_vegetation", "max_m"] < 2.0 and t.loc["no_vegetation", "median_m"] == pytest.approx(0.0)


def test_params_take_their_keys_of_the_validate_section():
    from conftest import REPO
    from kitegully.config import load_yaml
    from kitegully.evaluate import CheckpointParams, TruthParams

    v = load_yaml(REPO / "config/sites/kamech_twin.yaml")["validate"]
    cp = CheckpointParams.from_config(v)
    assert cp.bare_classes == tuple(v["bare_classes"]) and cp.histogram_bins == v["histogram_bins"]
    sub = {k: v[k] for k in ("vegetation_classes", "error_limit_m", "figure_max_px", "profile")}
    tp = TruthParams.from_config(sub)
    assert tp.profile.reference == v["profile"]["reference"]
    with pytest.raises(InputError, match=r"validate: missing key 'bare_classes'"):
        CheckpointParams.from_config(sub)
    with pytest.raises(InputError, match=r"validate.profile.reference: must be dtm or dsm"):
        TruthParams.from_config({**sub, "profile": {**v["profile"], "reference": "dem"}})


def test_sd_without_blunders_leaves_out_gross_errors_only():
    from kitegully.evaluate.dem import sd_without_blunders

    rng = np.random.default_rng(7)
    e = rng.normal(0.01, 0.05, 466)
    sd, kept = sd_without_blunders(e)
    assert kept.all() and sd == pytest.approx(e.std(ddof=1))  # no blunder: the plain SD (4 NMAD passes 0.99994)
    with_blunders = np.concatenate([e, [5.31, -2.2], [np.nan]])
    sd2, kept2 = sd_without_blunders(with_blunders)
    assert kept2.size == 468 and (~kept2).sum() == 2 and not kept2[-2:].any()
    assert sd2 == pytest.approx(sd)
    assert sd_without_blunders(with_blunders, None)[0] > 5 * sd  # as the plain SD
    assert np.isnan(sd_without_blunders(np.array([0.1]))[0])
    sd3, kept3 = sd_without_blunders(np.array([0.0, 0.0, 0.0, 1.0]))  # NMAD 0: nothing can be judged
    assert kept3.all() and sd3 == pytest.approx(0.5)
