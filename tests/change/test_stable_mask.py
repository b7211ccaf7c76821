"""Stable ground restricted to masks flagged ``stable`` (kitegully.change.budget.stable_only, issue 17).

The DSMs' error can move between epochs by a different amount over different covers (the full-size corner:
ploughed soil +0.050 m, vegetation +0.030 m; docs/stages/11_kamech_full.md "Session 42"). Co-registered on the
vegetated ground, the soil keeps the difference; on unchanged ground of the soil's own cover (a track) it does not.
"""

from __future__ import annotations

import geopandas as gpd
import numpy as np
import pandas as pd
import pytest
import rasterio
from shapely.geometry import box

from change.change_synth import CRS, noise, terrain, write, xy
from change.test_tiles import PARAMS, _outs, _run_tiles
from kitegully import InputError
from kitegully.change import budget as bg
from kitegully.change.stage import detect_change
from kitegully.io.raster import GridSpec
from kitegully.terrain.tiling import TilingParams


def _site(d):
    """Soil (x < 40 m, its DSM error +0.05 m higher at epoch 2) lowered 0.1 m except on a track strip; grass +0.03 m."""
    g = GridSpec(500000.0, 4100000.0, 0.5, 140, 160, CRS)
    X, Y = xy(g)
    z = terrain(X, Y)
    soil = X - g.x0 < 40.0
    track = soil & (np.abs(X - g.x0 - 20.0) < 2.0)
    change = np.where(soil & ~track, -0.1, 0.0)
    z1 = z + noise(g, 0.02, "s1")
    z2 = z + change + np.where(soil, 0.05, 0.03) + noise(g, 0.02, "s2")
    files = dict(dem1=write(d / "dem1.tif", z1, g), dem2=write(d / "dem2.tif", z2, g))
    gpd.GeoDataFrame({"id": [1]}, geometry=[box(g.x0, g.y0 - 80, g.x0 + 40, g.y0)], crs=CRS).to_file(d / "soil.gpkg")
    gpd.GeoDataFrame({"id": [1]}, geometry=[box(g.x0 + 18.5, g.y0 - 80, g.x0 + 21.5, g.y0)], crs=CRS).to_file(d / "track.gpkg")
    epochs = [dict(name="e1", dem=files["dem1"], nodata=None, accuracy=dict(sd_m=0.02)),
              dict(name="e2", dem=files["dem2"], nodata=None, accuracy=dict(sd_m=0.02))]
    soil_mask = dict(name="soil", file=str(d / "soil.gpkg"), kind="vector", by=None, unstable=True)
    track_mask = dict(name="track", file=str(d / "track.gpkg"), kind="vector", by=None, stable=True)
    true_net = float(change[soil].sum() * g.cell ** 2)
    return epochs, soil_mask, track_mask, true_net


def test_candidates_are_outside_the_unstable_masks_or_inside_the_stable_ones(tmp_path):
    _, soil, track, _ = _site(tmp_path)
    g = GridSpec(500000.0, 4100000.0, 0.5, 140, 160, CRS)
    groups = bg.mask_groups([soil, track], g)
    outside = bg.stable_candidates([soil], groups, (160, 140))
    assert not outside[:, :80].any() and outside[:, 80:].all()
    # the stable track lies inside the unstable soil: the flag wins there, and nothing else is a candidate
    only = bg.stable_candidates([soil, track], groups, (160, 140))
    assert only.sum() == 6 * 160 and only[:, 37:43].all() and not only[:, :37].any() and not only[:, 43:].any()
    with pytest.raises(InputError, match="change.masks: track is flagged both stable and unstable"):
        bg.stable_candidates([soil, dict(track, unstable=True)], groups, (160, 140))


def _soil_row(out):
    b = pd.read_csv(out["budget"])
    return b[(b["mask"] == "soil") & (b["method"] == "raw")].iloc[0]


def test_stable_ground_of_the_measured_cover_removes_the_cover_shift(tmp_path):
    epochs, soil, track, true_net = _site(tmp_path)
    plain = _outs(tmp_path / "plain")
    detect_change(epochs, [soil], None, PARAMS, plain, site_crs=CRS)
    on_track = _outs(tmp_path / "track_only")
    detect_change(epochs, [soil, track], None, PARAMS, on_track, site_crs=CRS)
    dz = {k: pd.read_csv(o["coregistration"]).set_index("quantity")["value"]["dz_at_centre"] for k, o in
          (("plain", plain), ("track", on_track))}
    assert dz["plain"] == pytest.approx(0.03, abs=0.005) and dz["track"] == pytest.approx(0.05, abs=0.005)
    err_plain = _soil_row(plain)["net_m3"] - true_net
    err_track = _soil_row(on_track)["net_m3"] - true_net
    assert err_plain > 0.015 * 40 * 80 * 0.8  # the grass datum leaves about +0.02 m on the soil
    assert abs(err_track) < 0.25 * abs(err_plain)
    with rasterio.open(on_track["stable"]) as s:
        stable = s.read(1) == 1
    assert stable.any() and not stable[:, :37].any() and not stable[:, 43:].any()


def test_tiled_stable_mask_equals_untiled(tmp_path):
    epochs, soil, track, _ = _site(tmp_path)
    ref = _outs(tmp_path / "untiled")
    detect_change(epochs, [soil, track], None, PARAMS, ref, site_crs=CRS)
    out, _, _ = _run_tiles(tmp_path, epochs, [soil, track], None, None, PARAMS, TilingParams(30.0, 70.0, 80.0))
    for k in ("dod", "stable"):
        with rasterio.open(ref[k]) as a, rasterio.open(out[k]) as b:
            assert np.array_equal(a.read(1), b.read(1), equal_nan=True), k
    pd.testing.assert_frame_equal(pd.read_csv(ref["coregistration"]), pd.read_csv(out["coregistration"]), check_exact=True)
