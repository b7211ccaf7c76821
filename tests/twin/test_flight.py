"""Flight simulation, GCP observations and the flight workflow on fabricated twin files."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from kitegully import InputError
from kitegully.config import load_yaml
from kitegully.io.raster import GridSpec, write_raster
from kitegully.twin.camera import Camera, camera_from_config
from kitegully.twin.exif import read_exif
from kitegully.twin.flight import FlightSettings, ou_process, read_extent, simulate_flight
from kitegully.twin.flight_gcps import digitise, read_odm_gcp_list, target_pixels, write_odm_gcp_list
from kitegully.twin.render import make_scene
from kitegully.twin.render_flight import core_mask, coverage

from snakemake_utils import run_snakemake

REPO = Path(__file__).resolve().parents[2]
TINY = REPO / "config" / "sites" / "tiny_twin.yaml"
X0, Y0 = 578800.0, 4081500.0  # tiny tile origin (lower-left), UTM 32N
EXTENT = (X0, Y0, X0 + 200.0, Y0 + 200.0)


def tiny_flight_cfg(**over):
    cfg = dict(load_yaml(TINY)["flight"])
    cfg.update(over)
    return cfg


def const_offset(down=130.0, up=210.0):
    return lambda L: (down, up)


def test_flight_geometry_follows_operator_and_noise_models():
    cfg = tiny_flight_cfg(gps_correlation_s=2.0)
    s = FlightSettings.from_config(cfg, cfg["line_lengths_m"])
    cam = camera_from_config(cfg["camera"])
    res = simulate_flight(EXTENT, cam, s, const_offset(), lambda x, y: np.full_like(x, 100.0), np.random.default_rng(4))
    p = res.poses
    assert 6 <= len(p) <= 20
    # camera = operator + downwind offset (+ jitter of sd 2 m, correlation 8 s)
    rel = p[["x_m", "y_m"]].to_numpy() - p[["operator_x_m", "operator_y_m"]].to_numpy()
    down = np.radians(s.wind_from_deg + 180)
    expect = 130.0 * np.array([np.sin(down), np.cos(down)])
    assert np.abs(rel - expect).max() < 5 * s.jitter_horizontal_m
    track = res.camera_track.merge(res.operator_track, on="time_s", suffixes=("_c", "_o"))
    dxy = track[["x_m_c", "y_m_c"]].to_numpy() - track[["x_m_o", "y_m_o"]].to_numpy() - expect
    n_eff = track["time_s"].iloc[-1] / (2 * s.jitter_correlation_s)
    assert np.abs(dxy.mean(axis=0)).max() < 4 * s.jitter_horizontal_m / np.sqrt(n_eff)
    dz = track["z_m_c"] - track["z_m_o"] - (210.0 - s.rig_below_kite_m)
    assert abs(dz.mean()) < 4 * s.jitter_vertical_m / np.sqrt(n_eff)
    # pendulum tilt: a few degrees (amplitude 3°, plus 0.3·amp of irregular swing)
    amp = s.tilt_amplitude_deg
    assert np.abs(p[["omega_deg", "phi_deg"]].to_numpy()).max() < amp + 4 * 0.3 * amp
    # yaw drifts around the vane direction (downwind + offset)
    dyaw = (p["heading_deg"] - s.base_heading_deg + 180) % 360 - 180
    assert np.abs(dyaw).max() < 5 * s.yaw_sd_deg
    # intervalometer: kept images are whole multiples of the trigger interval apart
    dt = np.diff(p["time_s"].to_numpy())
    assert np.allclose(dt / s.trigger_interval_s, np.rint(dt / s.trigger_interval_s), atol=0.02)
    # GPS logger noise: sd 3 m per axis (n_eff ≈ T / (2·2 s) ≫ 100 → ±20 %)
    g = res.camera_gps
    ex = g["x_m"] - np.interp(g["time_s"], res.camera_track["time_s"], res.camera_track["x_m"])
    assert ex.std() == pytest.approx(s.gps_sigma_m, rel=0.2)
    assert len(g) == pytest.approx(res.camera_track["time_s"].iloc[-1] / s.gps_interval_s + 1, abs=1)


def test_flight_covers_core_with_three_images_and_target_overlap():
    cfg = tiny_flight_cfg()
    s = FlightSettings.from_config(cfg, cfg["line_lengths_m"])
    cam = camera_from_config(cfg["camera"])
    res = simulate_flight(EXTENT, cam, s, const_offset(), lambda x, y: np.full_like(x, 100.0), np.random.default_rng(0))
    dsm = np.full((100, 100), 100.0, np.float32)
    scene = make_scene(dsm, (X0, Y0 + 200), 2.0, np.zeros((1, 8, 8), np.uint8), (X0, Y0 + 200), 25.0, ("R",))
    xs, ys, counts, ov = coverage(cam, res.poses, scene, EXTENT, 4.0)
    core = core_mask(xs, ys, EXTENT, 20.0)
    assert counts[core].min() >= 3
    # kept every k-th shot so overlap ≈ target (jitter and yaw drift move it a little)
    assert ov["forward_overlap"].mean() == pytest.approx(s.forward_overlap, abs=0.1)


def test_ou_process_statistics():
    x = ou_process(np.random.default_rng(0), 200000, 0.1, 2.0, 1.0)
    assert x.std() == pytest.approx(2.0, rel=0.05)
    lag = int(1.0 / 0.1)
    assert np.corrcoef(x[:-lag], x[lag:])[0, 1] == pytest.approx(np.exp(-1), abs=0.05)


def test_kite_offset_from_tether_model():
    pytest.importorskip("kitegully.tether.line")
    from kitegully.twin.flight import tether_kite_offset

    cfg = load_yaml(TINY)
    off = tether_kite_offset(cfg["tether"], "dyneema", "delta10", 6.0)
    d150, h150 = off(150.0)
    d250, h250 = off(250.0)
    assert h250 > h150 > 100.0  # Table 2: 150 m of Dyneema flies at ~120 m
    assert 50 < np.degrees(np.arctan2(h150, d150)) < 62  # flight angle below the 60° pull, close to it
    with pytest.raises(InputError, match="flight.material"):
        tether_kite_offset(cfg["tether"], "kevlar", "delta10", 6.0)


def _target_scene(targets: pd.DataFrame):
    n = 1000  # 200 m at 0.2 m
    xs = X0 + (np.arange(n) + 0.5) * 0.2
    X, Y = np.meshgrid(xs, Y0 + 200 - (np.arange(n) + 0.5) * 0.2)
    dsm = (100 + 0.05 * (X - X0) + 3 * np.sin((Y - Y0) / 30)).astype(np.float32)
    return make_scene(dsm, (X0, Y0 + 200), 0.2, np.full((3, 16, 16), 80, np.uint8), (X0, Y0 + 200), 12.5,
                      ("R", "G", "B")), dsm


def test_gcp_observations_parse_and_agree_with_truth_within_click_noise(tmp_path):
    cfg = tiny_flight_cfg()
    s = FlightSettings.from_config(cfg, cfg["line_lengths_m"])
    cam = camera_from_config(cfg["camera"])
    res = simulate_flight(EXTENT, cam, s, const_offset(), lambda x, y: np.full_like(x, 100.0), np.random.default_rng(1))
    rng = np.random.default_rng(2)
    xy = rng.uniform(20, 180, (12, 2))
    targets = pd.DataFrame({"gcp_id": [f"GCP{i + 1:02d}" for i in range(12)], "x": X0 + xy[:, 0], "y": Y0 + xy[:, 1]})
    targets["z"] = 100 + 0.05 * xy[:, 0] + 3 * np.sin(xy[:, 1] / 30)
    targets["size_m"] = 1.0
    scene, _ = _target_scene(targets)
    truth = target_pixels(cam, res.poses, targets, scene, 20.0, 0.1)
    assert truth["fully_in_view"].any()
    sigma = 0.7
    obs = digitise(truth, cam, np.random.default_rng(3), sigma, 6)
    survey = targets[["gcp_id", "x", "y", "z"]].copy()
    survey[["x", "y", "z"]] += np.random.default_rng(4).normal(0, 0.015, (12, 3))
    write_odm_gcp_list(tmp_path / "gcp_list.txt", "EPSG:32632", obs, survey)
    proj, parsed = read_odm_gcp_list(tmp_path / "gcp_list.txt")
    assert proj == "EPSG:32632"
    assert len(parsed) == len(obs) > 20
    m = parsed.merge(truth, on=["image", "gcp_id"], suffixes=("", "_true"))
    assert len(m) == len(parsed) and m["fully_in_view"].all()  # only targets fully in view
    err = np.concatenate([m["im_x_px"] - m["im_x_px_true"], m["im_y_px"] - m["im_y_px_true"]])
    # click noise σ = 0.7 px per axis (file rounds to 0.01 px): all within 5σ, rms ≈ σ
    assert np.abs(err).max() < 5 * sigma
    assert np.sqrt(np.mean(err**2)) == pytest.approx(sigma, rel=0.3)
    sv = survey.set_index("gcp_id")
    assert np.allclose(parsed["geo_x"], sv.loc[parsed["gcp_id"], "x"], atol=1e-3)
    per_target = parsed.groupby("gcp_id").size()
    assert per_target.max() <= 6
    # every target seen fully in ≥ 3 images is digitised in ≥ 3
    seen = truth[truth["fully_in_view"]].groupby("gcp_id").size()
    assert (per_target.reindex(seen[seen >= 3].index) >= 3).all()


def test_gcp_list_errors(tmp_path):
    p = tmp_path / "gcp_list.txt"
    p.write_text("EPSG:32632\n1 2 3 4 5 IMG_0001.jpg\n")
    with pytest.raises(InputError, match="gcp_list.txt: line 2"):
        read_odm_gcp_list(p)
    p.write_text("")
    with pytest.raises(InputError, match="empty"):
        read_odm_gcp_list(p)
    with pytest.raises(InputError, match="site.json"):
        (tmp_path / "site.json").write_text(json.dumps({"extent": {"xmin": 5, "ymin": 0, "xmax": 1, "ymax": 3}}))
        read_extent(tmp_path / "site.json")


# ----------------------------------------------------------------------------- workflow


def fabricate_twin(twin: Path, seed: int = 0) -> pd.DataFrame:
    """Twin outputs by the contract: a hilly tile with a 'building', texture with targets."""
    from scipy import ndimage

    rng = np.random.default_rng(seed)
    cell, tcell, n = 0.2, 0.1, 1000
    grid = GridSpec(X0, Y0 + 200, cell, n, n, "EPSG:32632")
    dtm = 110 + ndimage.gaussian_filter(rng.normal(0, 1, (n, n)), 60) * 600
    dsm = dtm.copy()
    dsm[400:450, 600:660] += 6.0  # a building
    write_raster(twin / "truth" / "dtm.tif", dtm.astype(np.float32), grid)
    write_raster(twin / "truth" / "dsm.tif", dsm.astype(np.float32), grid)
    nt = 2000
    tex = np.zeros((nt, nt))
    for s, a in [(1, 25), (4, 20), (16, 15)]:
        o = ndimage.gaussian_filter(rng.normal(0, 1, (nt // s, nt // s)), 1.0)
        tex += np.kron(o / o.std(), np.ones((s, s)))[:nt, :nt] * a
    bands = np.stack([70 + tex, 65 + 0.9 * tex, 50 + 0.7 * tex, 120 + 0.5 * tex])
    xy = np.array([[40, 40], [100, 60], [160, 40], [50, 150], [100, 140], [160, 160], [130, 100], [70, 100]], float)
    for x, y in xy:
        c0, r0 = int((x - 0.5) / tcell), int((200 - y - 0.5) / tcell)
        bands[:, r0 : r0 + 10, c0 : c0 + 10] = 240
    tgrid = GridSpec(X0, Y0 + 200, tcell, nt, nt, "EPSG:32632")
    write_raster(twin / "truth" / "texture.tif", np.clip(bands, 0, 255).astype(np.uint8), tgrid,
                 band_names=["R", "G", "B", "NIR"])
    r, c = (200 - xy[:, 1]) / cell - 0.5, xy[:, 0] / cell - 0.5
    z = ndimage.map_coordinates(dsm, [r, c], order=1)
    targets = pd.DataFrame({"gcp_id": [f"GCP{i + 1}" for i in range(len(xy))], "x": X0 + xy[:, 0], "y": Y0 + xy[:, 1],
                            "z": z, "size_m": 1.0})
    targets.to_csv(twin / "truth" / "targets.csv", index=False)
    (twin / "observed").mkdir(parents=True, exist_ok=True)
    survey = targets[["gcp_id", "x", "y", "z"]].copy()
    survey[["x", "y", "z"]] += rng.normal(0, 0.015, (len(xy), 3))
    survey.to_csv(twin / "observed" / "gcp_survey.csv", index=False)
    (twin / "site.json").write_text(json.dumps({"crs": "EPSG:32632", "extent": dict(zip(["xmin", "ymin", "xmax", "ymax"], EXTENT)),
                                                "dem_cell_m": cell, "texture_cell_m": tcell}))
    return targets


def test_flight_workflow_on_fabricated_twin(tmp_path):
    results = tmp_path / "results"
    twin = results / "tiny_twin" / "twin"
    targets = fabricate_twin(twin)
    fl = results / "tiny_twin" / "flight"
    wanted = ["observed/gcp_list.txt", "observed/camera_gps.gpx", "observed/operator_gps.gpx", "flight_summary.csv",
              "flight_map.png", "sample_images.png"]
    # the fabricated twin files are newer than anything a twin rule depends on, so only the
    # flight rules run
    run_snakemake(TINY, results, [str(fl / w) for w in wanted], cores=2)
    for w in wanted:
        assert (fl / w).exists(), w
    poses = pd.read_csv(fl / "truth" / "poses.csv")
    images = sorted((fl / "observed" / "images").glob("*.jpg"))
    assert [p.name for p in images] == sorted(poses["image"])
    assert 6 <= len(images) <= 20
    cam = Camera.read_json(fl / "truth" / "camera.json")
    ex = read_exif(images[0])
    assert ex["model"] == "NEX-5N" and ex["focal_length_mm"] == pytest.approx(18.0)
    assert (ex["width"], ex["height"]) == (cam.width, cam.height)
    proj, obs = read_odm_gcp_list(fl / "observed" / "gcp_list.txt")
    assert proj == "EPSG:32632"
    assert set(obs["gcp_id"]) <= set(targets["gcp_id"]) and len(obs) >= 8
    truth = pd.read_csv(fl / "truth" / "gcp_pixels.csv")
    m = obs.merge(truth, on=["image", "gcp_id"], suffixes=("", "_true"))
    assert np.hypot(m["im_x_px"] - m["im_x_px_true"], m["im_y_px"] - m["im_y_px_true"]).max() < 5 * 0.7
    gpx = ET.parse(fl / "observed" / "camera_gps.gpx")
    pts = gpx.getroot().findall(".//{http://www.topografix.com/GPX/1/1}trkpt")
    assert len(pts) > 100 and 35 < float(pts[0].get("lat")) < 38  # Cap Bon latitude
    summary = pd.read_csv(fl / "flight_summary.csv").set_index("quantity")["value"]
    assert summary["core_images_per_point_min"] >= 3
    # observed and truth kept apart: nothing under observed/ names truth
    assert not any("truth" in p.name for p in (fl / "observed").rglob("*"))


def test_same_seed_same_flight_and_bad_inputs(tmp_path):
    cfg = tiny_flight_cfg()
    s = FlightSettings.from_config(cfg, cfg["line_lengths_m"])
    cam = camera_from_config(cfg["camera"])
    runs = [simulate_flight(EXTENT, cam, s, const_offset(), lambda x, y: np.full_like(x, 100.0),
                            np.random.default_rng(9)) for _ in range(2)]
    pd.testing.assert_frame_equal(runs[0].poses, runs[1].poses)
    pd.testing.assert_frame_equal(runs[0].camera_gps, runs[1].camera_gps)
    with pytest.raises(InputError, match="start_time"):
        FlightSettings.from_config({**cfg, "start_time": "yesterday"}, cfg["line_lengths_m"])
    with pytest.raises(InputError, match="line_lengths_m"):
        simulate_flight(EXTENT, cam, s, lambda L: (10.0, -5.0), lambda x, y: np.full_like(x, 100.0),
                        np.random.default_rng(0))
    from kitegully.twin.render_flight import load_scene

    twin = tmp_path / "twin"
    fabricate_twin(twin)
    with pytest.raises(InputError, match="texture.tif: no band named 'SWIR'"):
        load_scene(twin / "truth" / "dsm.tif", twin / "truth" / "texture.tif", ["R", "SWIR"], 16)
    grid = GridSpec(X0, Y0 + 200, 1.0, 200, 200, "EPSG:32632")
    write_raster(tmp_path / "nan.tif", np.full((200, 200), np.nan, np.float32), grid)
    with pytest.raises(InputError, match="nan.tif: DSM is all nodata"):
        load_scene(tmp_path / "nan.tif", twin / "truth" / "texture.tif", ["R"], 16)


def test_flight_settings_name_a_missing_or_unknown_key():
    cfg = tiny_flight_cfg()
    assert FlightSettings.from_config(cfg, cfg["line_lengths_m"]).walk_speed_m_s == float(cfg["walk_speed_m_s"])
    del cfg["walk_speed_m_s"]
    with pytest.raises(InputError, match="flight: missing key 'walk_speed_m_s'"):
        FlightSettings.from_config(cfg, [50.0])
    with pytest.raises(InputError, match="flight: unknown key 'walk_sped_m_s'"):
        FlightSettings.from_config({**tiny_flight_cfg(), "walk_sped_m_s": 1.0}, [50.0])
