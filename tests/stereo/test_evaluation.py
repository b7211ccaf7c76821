"""Evaluation of a pair against the twin: DEM error split into plane and rest, the matcher's achieved δ."""

import numpy as np
import pytest

from kitegully.io.raster import GridSpec
from kitegully.stereo.evaluation import error_decomposition, matching_residual_px
from kitegully.stereo.matching import Disparity
from kitegully.stereo.rectify import rectify_pair, relative_orientation_from_poses
from kitegully.stereo.rig import paper_rig


def test_error_decomposition_on_constructed_surfaces():

    grid = GridSpec(x0=-0.1, y0=0.1, cell=0.01, width=20, height=20, crs="EPSG:32632")
    X, Y = np.meshgrid(*grid.cell_centres())
    ref = 0.003 * np.sin(40 * X)
    noise = np.where((np.indices(X.shape).sum(axis=0) % 2) == 0, 1e-4, -1e-4)  # ±0.1 mm, zero mean, no tilt
    dem = ref + 2e-4 + 1e-3 * Y + noise  # 0.2 mm offset, 1 mm/m tilt
    dem[0, 0] = np.nan
    d = error_decomposition(dem, ref, grid)
    assert d["tilt_mm_per_m"] == pytest.approx(1.0, abs=0.02)
    assert d["residual_mae_mm"] == pytest.approx(0.1, abs=0.005)
    assert d["mean_error_mm"] == pytest.approx(0.2 + 1e3 * 1e-3 * np.nanmean(np.where(np.isfinite(dem), Y, np.nan)), abs=0.01)


def test_matching_residual_measures_a_known_disparity_error():
    """Disparity = ray-cast truth + N(0.2 px bias, 0.05 px) → the measured δ and bias are those values."""

    rig = paper_rig(2.7, 0.8)
    R, T = relative_orientation_from_poses(rig.pose_left, rig.pose_right)
    rect = rectify_pair(rig.left, rig.right, R, T, (2.6, 2.8))
    h = lambda x, y: 0.004 * np.sin(2 * np.pi * x / 0.12)  # noqa: E731
    # ray-cast the true disparity of every left rectified pixel over the box
    W, H_ = rect.size
    yy, xx = np.mgrid[0:H_, 0:W].astype(float)
    sel = (slice(600, 1100), slice(900, 1500))
    xs, ys = xx[sel].ravel(), yy[sel].ravel()
    P1 = rect.P1
    dirs = np.column_stack([(xs - P1[0, 2]) / P1[0, 0], (ys - P1[1, 2]) / P1[1, 1], np.ones_like(xs)])
    dw = (dirs @ rect.R1) @ rig.pose_left.R
    C = rig.pose_left.C
    t = -C[2] / dw[:, 2]
    for _ in range(8):
        Xw = C + t[:, None] * dw
        t = (h(Xw[:, 0], Xw[:, 1]) - C[2]) / dw[:, 2]
    Xw = C + t[:, None] * dw
    ur = rect.rectify_points(rig.right.project(Xw, rig.pose_right), "right")
    d = np.full((H_, W), np.nan)
    rng = np.random.default_rng(1)
    d[sel] = (xs - ur[:, 0] + 0.2 + rng.normal(0, 0.05, xs.size)).reshape(d[sel].shape)
    grid = GridSpec(x0=-0.05, y0=0.05, cell=0.005, width=20, height=20, crs="EPSG:32632")
    m = matching_residual_px(rect, Disparity(d, np.ones_like(d)), rig, h, grid)
    assert m["n"] > 2000
    assert m["bias_d_px"] == pytest.approx(0.2, abs=0.01)
    # bilinear interpolation of independent pixel errors averages them a little: σ between 0.5 and 1.0 × 0.05
    assert 0.025 < m["sigma_d_px"] < 0.052
    assert m["y_parallax_rms_px"] < 1e-6  # true orientation: no vertical parallax
