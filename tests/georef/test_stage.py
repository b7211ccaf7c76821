"""georef stage: a later epoch keeps the first epoch's camera (issue 17, epoch-2 camera heights)."""

import numpy as np
import pandas as pd
import pytest

from kitegully import InputError
from kitegully.georef.bundle import BundleSettings, adjust
from kitegully.georef.geometry import camera_centres
from kitegully.georef.model import transform_block
from kitegully.georef.similarity import umeyama
from kitegully.georef.stage import GeorefParams, with_calibration

from .test_bundle import gcp_errors, synthetic_block
from .test_control import PARAMS

SETTINGS = dict(sigma_tie_px=0.3, sigma_gcp_px=0.5, sigma_gcp_xy_m=0.01, sigma_gcp_z_m=0.01, max_iterations=60)


def _calibration_csv(path, intr):
    cols = ["f_px", "cx_px", "cy_px", "k1", "k2"]
    row = {f"{c}_adjusted": v for c, v in zip(cols, intr)}
    pd.DataFrame([{"camera_id": 1, **row}]).to_csv(path, index=False)
    return path


def _adjusted(model, survey, refine):
    Xm = gcp_errors(model, np.zeros_like(survey))
    sim = umeyama(Xm, survey)
    b = transform_block(model, sim)
    b.gcp_xyz = sim.apply(Xm)
    return adjust(b, survey, BundleSettings(refine=refine, **SETTINGS))[0]


def test_a_known_camera_removes_the_focal_length_height_error(tmp_path):
    # the epoch-2 mechanism: a self-calibrated nadir block trades focal length against
    # flying height (dz = H·Δf/f); with the camera the stronger first epoch calibrated
    # (here the true one) fixed, the block's cameras sit at their true height
    model, survey, G, C, _ = synthetic_block(seed=5, k1_start=-0.05)
    true_intr = np.array([1200.0, 800.0, 600.0, -0.05, 0.01])
    free = _adjusted(model, survey, ("f", "cx", "cy", "k1", "k2"))
    fixed = _adjusted(with_calibration(model, _calibration_csv(tmp_path / "cal.csv", true_intr)), survey, ())
    dz_free = camera_centres(free.rv, free.t)[:, 2] - C[:, 2]
    dz_fixed = camera_centres(fixed.rv, fixed.t)[:, 2] - C[:, 2]
    assert np.allclose(fixed.intr[0], true_intr)
    assert abs(np.mean(dz_fixed)) < 0.05 * 2  # within 2 GSD
    assert abs(np.mean(dz_free) - 60.0 * (free.intr[0, 0] - 1200.0) / 1200.0) < 2 * np.std(dz_free) + 0.05


def test_with_calibration_checks_the_file(tmp_path):
    model, *_ = synthetic_block()
    bad = tmp_path / "bad.csv"
    pd.DataFrame({"camera_id": [1], "f_px_adjusted": [1200.0]}).to_csv(bad, index=False)
    with pytest.raises(InputError, match="needs one row per camera"):
        with_calibration(model, bad)
    with pytest.raises(InputError, match="cannot read the camera calibration"):
        with_calibration(model, tmp_path / "missing.csv")


def test_camera_from_first_epoch_is_optional_and_off_by_default():
    assert not GeorefParams.from_config(PARAMS).camera_from_first_epoch
    assert GeorefParams.from_config({**PARAMS, "camera_from_first_epoch": True}).camera_from_first_epoch
