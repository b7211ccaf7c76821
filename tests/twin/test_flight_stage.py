"""The flight stage's products (kitegully.twin.flight_stage) on a flat constructed twin."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
import shapely

from kitegully.config import load_yaml
from kitegully.io.raster import GridSpec
from kitegully.twin.camera import camera_from_config
from kitegully.twin.flight_stage import fly_kite, image_footprints
from snakemake_utils import REPO

SITE = load_yaml(REPO / "config" / "sites" / "tiny_twin.yaml")
X0, Y0 = 578800.0, 4081500.0
EXTENT = (X0, Y0, X0 + 200.0, Y0 + 200.0)
TETHER_KEYS = ("lines", "kites", "kite_model", "atmosphere", "segment_length_m")


def test_fly_kite_tables_and_seed():
    grid = GridSpec(X0, Y0 + 200.0, 1.0, 200, 200, "EPSG:32632")
    dtm = np.full((200, 200), 100.0, dtype=np.float32)
    dtm[:10, :10] = np.nan  # holes: filled with the median, the operator still walks
    flight = {k: v for k, v in SITE["flight"].items() if k not in ("render", "gcps", "coverage", "figures", "threads")}
    tether = {k: SITE["tether"][k] for k in TETHER_KEYS}
    a = fly_kite(EXTENT, dtm, grid, flight, tether, seed=7)
    b = fly_kite(EXTENT, dtm, grid, flight, tether, seed=7)
    assert a.poses.equals(b.poses) and a.camera_gps.equals(b.camera_gps)
    assert not fly_kite(EXTENT, dtm, grid, flight, tether, seed=8).camera_gps.equals(a.camera_gps)
    # tracks decimated to 1 s steps
    assert np.allclose(np.diff(a.operator_track["time_s"]), 1.0)
    assert len(a.camera_track) == len(a.operator_track)
    # the operator walks on the flat DTM at hand height
    assert np.allclose(a.operator_track["z_m"], 100.0 + flight["operator_hand_height_m"])
    assert list(a.strips.columns) == [
        "strip", "operator_start_x_m", "operator_start_y_m", "operator_end_x_m", "operator_end_y_m", "line_length_m",
        "kite_downwind_m", "camera_height_m", "footprint_along_m", "footprint_across_m", "keep_every_nth_shot",
    ]
    assert set(a.poses["strip"]) <= set(a.strips["strip"])
    assert (a.strips["camera_height_m"] > 0).all()


def test_image_footprints_of_a_nadir_camera_over_flat_ground():
    camera = camera_from_config({**SITE["flight"]["camera"], "k1": 0.0, "k2": 0.0})  # no lens distortion
    h = 150.0
    poses = pd.DataFrame({"image": ["a"], "x_m": [X0], "y_m": [Y0], "z_m": [h], "heading_deg": [0.0],
                          "omega_deg": [0.0], "phi_deg": [0.0]})
    gsd = pd.Series({"a": h / camera.f})
    (poly,) = image_footprints(camera, poses, gsd)
    sides = np.ptp(poly, axis=0)
    # nadir footprint H·S/f, each side (width and height in some order)
    assert sorted(sides) == pytest.approx(sorted(camera.footprint(h)), rel=1e-6)
    # the camera sees the ground below it (the principal point may be off the image centre)
    assert shapely.Polygon(poly).contains(shapely.Point(X0, Y0))


def test_flight_summary_rows():
    from kitegully.twin.flight_stage import flight_summary

    poses = pd.DataFrame({"image": ["a", "b", "c"], "strip": [0, 0, 1]})
    stats = pd.DataFrame({"gsd_m": [0.02, 0.03, 0.04], "blur_px": [0.1, 0.5, 0.2]})
    overlap = pd.DataFrame({"forward_overlap": [0.7, 0.8]})
    obs = pd.DataFrame({"gcp_id": ["G1", "G1", "G2"]})
    per_target = pd.Series({"G1": 2, "G2": 1, "G3": 0})
    t = flight_summary(poses, stats, overlap, np.array([2, 3, 4, 5]), obs, per_target, 3, 6.0, 9.0, 2).set_index("quantity")
    assert t.loc["images", "value"] == 3 and t.loc["strips", "value"] == 2
    assert t.loc["gsd_median", "value"] == pytest.approx(0.03) and t.loc["gsd_median", "unit"] == "m"
    assert t.loc["core_share_with_3_or_more", "value"] == pytest.approx(0.75)
    assert t.loc["gcp_targets_digitised", "value"] == 2 and t.loc["gcp_targets_min_images", "value"] == 0
    assert t.loc["render_time_per_image", "value"] == pytest.approx(2.0)
