"""Real kite photos (Boruszyn): SfM on the first ten images at 800 px and the GCP pixel frame.

Skips where ../shared/data is absent. The ten images include img_4909, the one file
without an EXIF rotation tag: in the stored frame it must share the camera of the others.
"""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from kitegully.georef.gcp_io import read_gcps
from kitegully.georef.model import block_from_reconstruction
from kitegully.georef.observations import collect_observations, triangulate_gcps
from kitegully.sfm import SfmParams, load_image_infos, reconstruct_model

PARAMS = {
    "image_frame": "stored", "max_image_size": 800, "skip_unreadable": False, "jpeg_quality": 95,
    "camera_model": "RADIAL", "default_focal_factor": 1.2, "max_num_features": 4096,
    "first_octave": -1, "refine_principal_point": False, "min_num_matches": 15,
    "matching": {
        "method": "exhaustive", "overlap": 10, "exhaustive_max_images": 60, "camera_log": None,
        "log_time_offset_s": 0.0, "log_max_gap_s": 5.0, "gps_sigma_m": 3.0,
        "spatial_max_distance_m": 250.0, "spatial_max_neighbors": 20,
    }, "threads": 2, "deterministic": False,
}


@pytest.fixture(scope="module")
def small_run(boruszyn_dir, tmp_path_factory):
    tmp = tmp_path_factory.mktemp("boruszyn")
    src = tmp / "images"
    src.mkdir()
    for p in sorted((boruszyn_dir / "images").glob("*.jpg"))[:10]:
        shutil.copy(p, src / p.name)
    summary = reconstruct_model(src, tmp / "work", tmp / "model", tmp / "summary.json", tmp / "images.csv",
                               tmp / "info.json", SfmParams.from_config(PARAMS), seed=11, threads=2)
    return tmp, summary


@pytest.mark.slow
@pytest.mark.realdata
def test_ten_images_register_with_one_camera(small_run):
    tmp, s = small_run
    assert s["n_images"] == 10
    assert s["n_registered"] >= 9  # >= 90 % (issue 5 target)
    assert s["mean_reprojection_error_px"] < 1.0
    assert len(s["cameras"]) == 1  # the untagged img_4909 shares the sensor-frame camera
    # EXIF: 5 mm at 1.43 um pixels = 3502 px at 4608 px -> 608 px at 800 px; self-calibration within 15 %
    assert s["cameras"][0]["f"] == pytest.approx(608, rel=0.15)
    assert (tmp / "summary.json").exists() and (tmp / "images.csv").exists()


@pytest.mark.slow
@pytest.mark.realdata
def test_gcp_file_pixels_are_stored_frame_at_2400px(small_run, boruszyn_dir):
    """GCP1 and GCP2 are each seen in two of the ten images: their rays meet only in the
    stored frame at 2400 px (documented in config/sites/boruszyn_kap.yaml)."""
    import pycolmap

    tmp, _ = small_run
    infos = load_image_infos(tmp / "info.json")
    block, index = block_from_reconstruction(pycolmap.Reconstruction(str(tmp / "model")), 0, 0)
    rows = {n.split("/")[-1]: k for k, n in enumerate(index.image_names)}
    gcps = read_gcps(boruszyn_dir / "gcp_list.txt", "EPSG:2180")
    errs = {}
    for frame, scale in (("stored", 2400 / 4608), ("stored", 1.0), ("display", 2400 / 4608), ("display", 1.0)):
        obs = collect_observations(gcps, infos, rows, frame, "stored", scale, 0.1, 0.0)
        two = [o for o in obs if len(o.rows) >= 2]
        _, rp = triangulate_gcps(block, two)
        errs[(frame, scale)] = rp
    good = errs[("stored", 2400 / 4608)]
    assert len(good) == 2 and np.all(good < 4.0)  # px at 800 px: natural features, 2 views
    for key, rp in errs.items():
        if key != ("stored", 2400 / 4608):
            assert np.max(rp) > 5 * np.max(good), key


def test_params_name_the_bad_key():
    from kitegully import InputError

    with pytest.raises(InputError, match=r"sfm.matching.method: must be one of"):
        SfmParams.from_config({**PARAMS, "matching": {**PARAMS["matching"], "method": "vocab_tree"}})
    with pytest.raises(InputError, match=r"sfm: unknown key 'max_size'"):
        SfmParams.from_config({**PARAMS, "max_size": 10})
    p = SfmParams.from_config(PARAMS)
    assert p.matching.method == "exhaustive" and p.max_image_size == 800
