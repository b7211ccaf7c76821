"""Spatial matching: camera positions from a GPS log at EXIF capture times; method choice."""

import dataclasses

import numpy as np
import pandas as pd
import pytest

from kitegully import InputError
from kitegully.sfm.images import ImageInfo
from kitegully.sfm.priors import positions_from_log
from kitegully.sfm.reconstruct import choose_matching_method

CRS = "EPSG:32632"


def _info(name: str, time: str) -> ImageInfo:
    fields = {f.name: None for f in dataclasses.fields(ImageInfo)}
    fields.update(name=name, sfm_name=f"s_{name}", capture_time=time)
    return ImageInfo(**fields)


def _log(tmp_path, offset_hours=0):
    t = pd.date_range("2013-09-10T08:00:00Z", periods=100, freq="1s") + pd.Timedelta(hours=offset_hours)
    df = pd.DataFrame({"time": t.strftime("%Y-%m-%dT%H:%M:%SZ"), "x": 578000 + 2.0 * np.arange(100), "y": 4081000.0, "z": 400.0})
    path = tmp_path / "camera.csv"
    df.to_csv(path, index=False)
    return path


def test_positions_interpolated_at_capture_times(tmp_path):
    infos = [_info("a.jpg", "2013-09-10T08:00:10"), _info("b.jpg", "2013-09-10T08:00:50"), _info("c.jpg", "")]
    pos = positions_from_log(infos, _log(tmp_path), CRS, time_offset_s=0.0, max_gap_s=5.0)
    assert set(pos) == {"s_a.jpg", "s_b.jpg"}  # no capture time, no position
    np.testing.assert_allclose(pos["s_a.jpg"], [578020.0, 4081000.0, 400.0])
    # a camera clock 5 s ahead of GPS: the photo was taken 5 s earlier in GPS time
    pos = positions_from_log(infos, _log(tmp_path), CRS, time_offset_s=5.0, max_gap_s=5.0)
    np.testing.assert_allclose(pos["s_b.jpg"][0], 578000.0 + 2 * 45)


def test_log_outside_the_photo_times_is_a_clear_error(tmp_path):
    infos = [_info("a.jpg", "2013-09-10T08:00:10")]
    with pytest.raises(InputError, match="no photo's capture time falls inside") as err:
        positions_from_log(infos, _log(tmp_path, offset_hours=2), CRS, 0.0, 5.0)
    assert "camera.csv" in str(err.value)


@pytest.mark.parametrize(
    "method, n, priors, expected",
    [("auto", 20, 0, "exhaustive"), ("auto", 57, 57, "spatial"), ("auto", 57, 0, "sequential"), ("exhaustive", 57, 57, "exhaustive")],
)
def test_choose_matching_method(method, n, priors, expected):
    assert choose_matching_method(method, n, 30, priors) == expected


def test_spatial_without_positions_is_refused():
    with pytest.raises(InputError, match="camera_log"):
        choose_matching_method("spatial", 57, 30, 0)
    with pytest.raises(InputError, match="not one of"):
        choose_matching_method("vocabtree", 57, 30, 0)


def test_spatial_neighbours_are_horizontal(tmp_path):
    """A photo 400 m higher over the same ground is a neighbour; one 1 km to the side is not."""
    import sqlite3

    import pycolmap
    from PIL import Image

    from kitegully.sfm.priors import write_position_priors
    from kitegully.sfm.reconstruct import match_features

    rng = np.random.default_rng(5)
    tex = np.kron(rng.integers(0, 255, (60, 80)).astype(np.uint8), np.ones((4, 4), np.uint8))
    (tmp_path / "img").mkdir()
    for name in ("low.jpg", "high.jpg", "far.jpg"):
        Image.fromarray(np.repeat(tex[:, :, None], 3, axis=2)).save(tmp_path / "img" / name, quality=95)
    db = tmp_path / "database.db"
    ext = pycolmap.FeatureExtractionOptions()
    ext.num_threads = 1
    pycolmap.extract_features(db, tmp_path / "img", extraction_options=ext, device=pycolmap.Device.cpu)
    pos = {"low.jpg": np.array([0.0, 0.0, 100.0]), "high.jpg": np.array([30.0, 0.0, 500.0]),
           "far.jpg": np.array([1000.0, 0.0, 100.0])}
    n = write_position_priors(db, pos, 3.0)
    assert match_features(db, 3, "spatial", 10, 30, 1, n, spatial_max_distance_m=250.0, spatial_max_neighbors=20) == "spatial"
    con = sqlite3.connect(str(db))
    names = dict(con.execute("SELECT image_id, name FROM images"))
    pairs = set()
    for (pid,) in con.execute("SELECT pair_id FROM matches"):
        b = pid % 2147483647
        pairs.add(frozenset((names[(pid - b) // 2147483647], names[b])))
    con.close()
    assert pairs == {frozenset(("low.jpg", "high.jpg"))}
