import dataclasses

import numpy as np
import pytest
from scipy.ndimage import fourier_shift, gaussian_filter

from kitegully import InputError
from kitegully.io.raster import GridSpec
from kitegully.stereo.matching import MatchParams, disparity_to_points, grid_dem, match_epipolar, triangulate_points
from kitegully.stereo.rectify import relative_orientation_from_poses, rectify_pair
from kitegully.stereo.rig import paper_rig
from kitegully.stereo.synth import render_heightfield, soil_texture


def _texture(shape=(260, 420), seed=0):
    a = gaussian_filter(np.random.default_rng(seed).standard_normal(shape), 1.5)
    return a / a.std() * 30 + 128


@pytest.mark.parametrize("d_true", [17.37, 23.5])
def test_shifted_texture_recovers_known_disparity(d_true):
    a = _texture()
    b = np.fft.ifft2(fourier_shift(np.fft.fft2(a), (0, -d_true))).real  # right = left moved by −d (exact sub-pixel shift)
    disp = match_epipolar(a, b, (5.0, 40.0), MatchParams(levels=3), roi=(48, 16, 400, 240))
    v = disp.d[disp.valid]
    assert v.size > 0.9 * (400 - 48) * (240 - 16)
    assert abs(np.median(v) - d_true) < 0.02  # sub-pixel
    assert np.std(v) < 0.08
    assert np.isnan(disp.d[:16]).all()  # outside the region


def test_laplacian_pyramid_copes_with_brightness_difference():
    a = _texture(seed=1)
    b = np.fft.ifft2(fourier_shift(np.fft.fft2(a), (0, -12.25))).real * 0.8 + 20.0  # the other camera is darker
    disp = match_epipolar(a, b, (0.0, 30.0), MatchParams(levels=3, filter="log"), roi=(40, 16, 400, 240))
    assert abs(np.nanmedian(disp.d) - 12.25) < 0.02


def test_pair_with_no_overlap_is_rejected():
    a = _texture()
    with pytest.raises(InputError, match="matching: the pair has no overlap"):
        match_epipolar(a, a, (500.0, 600.0), MatchParams(levels=2), roi=(0, 0, 400, 200))
    with pytest.raises(InputError, match="must be 2-D with the same number of rows"):
        match_epipolar(a, a[:100], (0.0, 10.0))


def test_textureless_pair_gives_one_sentence():
    flat = np.full((200, 300), 100.0)
    with pytest.raises(InputError, match="no pixel of the pair matched"):
        match_epipolar(flat, flat, (0.0, 10.0), MatchParams(levels=2))


def test_grid_dem_means_per_cell():
    grid = GridSpec(x0=0.0, y0=1.0, cell=0.5, width=2, height=2, crs="EPSG:32632")
    pts = np.array([[0.1, 0.9, 1.0], [0.2, 0.8, 3.0], [0.7, 0.2, 5.0], [9.0, 9.0, 7.0]])
    dem = grid_dem(pts, grid)
    assert dem.data[0, 0] == pytest.approx(2.0)
    assert dem.data[1, 1] == pytest.approx(5.0)
    assert np.isnan(dem.data[0, 1]) and np.isnan(dem.data[1, 0])
    with pytest.raises(InputError, match="points must be an N × 3 array"):
        grid_dem(np.zeros((3, 2)), grid)


def test_rendered_pair_to_dem_end_to_end():
    """Small-frame version of the paper's rig over a relief of a few mm: DEM error ≪ the 1-px δz."""
    rig = paper_rig(2.7, 0.25)
    small = {s: dataclasses.replace(c, width=900, height=700, cx=c.cx - (2464 - 900) / 2, cy=c.cy - (1632 - 700) / 2)
             for s, c in (("left", rig.left), ("right", rig.right))}
    rig = dataclasses.replace(rig, left=small["left"], right=small["right"])
    rng = np.random.default_rng(5)
    tex = soil_texture(rng, (-0.35, -0.25, 0.35, 0.25), cell_m=4e-4)
    relief = lambda x, y: 0.006 * np.sin(30 * x) * np.cos(20 * y)  # noqa: E731
    L = render_heightfield(rig.left, rig.pose_left, relief, tex, noise_dn=1.0, rng=rng)
    Rimg = render_heightfield(rig.right, rig.pose_right, relief, tex, noise_dn=1.0, rng=rng)
    R, T = relative_orientation_from_poses(rig.pose_left, rig.pose_right)
    rect = rectify_pair(rig.left, rig.right, R, T, (2.6, 2.8))
    Lr, Rr = rect.remap(L, "left"), rect.remap(Rimg, "right")
    dr = rect.disparity_for_depth(np.array([2.8, 2.6]))
    box = np.array([[-0.08, -0.1, 0.0], [0.08, 0.1, 0.0]])
    (bx0, by0), (bx1, by1) = np.sort(rect.rectify_points(rig.left.project(box, rig.pose_left), "left"), axis=0)
    roi = (int(bx0), int(by0), int(bx1), int(by1))
    assert roi[2] - roi[0] > 250 and roi[3] - roi[1] > 300
    disp = match_epipolar(Lr, Rr, tuple(dr), MatchParams(levels=3), roi=roi)
    P = disparity_to_points(disp, rect, rig.pose_left, step=2)
    assert len(P) > 5000
    err = P[:, 2] - relief(P[:, 0], P[:, 1])
    dz1 = 2.7 * 2.7 / 0.25 * 0.0094 / 51.4  # δz of 1 px (m), 5.3 mm
    assert np.median(np.abs(err)) < 0.15 * dz1
    grid = GridSpec(x0=-0.05, y0=0.1, cell=0.01, width=10, height=20, crs="EPSG:32632")
    dem = grid_dem(P, grid, min_count=3)
    assert dem.valid.mean() > 0.8
    # point measurement through triangulatePoints agrees with the Q-matrix path
    yy, xx = np.nonzero(disp.valid)
    i = slice(0, 50)
    uvl = np.column_stack([xx[i], yy[i]]).astype(float)
    uvr = uvl - np.column_stack([disp.d[yy[i], xx[i]], np.zeros(50)])
    Xt = triangulate_points(rect, uvl, uvr, rig.pose_left)
    Xq = disparity_to_points(dataclasses.replace(disp, d=np.where(np.isin(np.arange(disp.d.size).reshape(disp.d.shape),
                                                                          yy[i] * disp.d.shape[1] + xx[i]), disp.d, np.nan)),
                             rect, rig.pose_left)
    assert np.allclose(np.sort(Xt[:, 2]), np.sort(Xq[:, 2]), atol=1e-6)
