"""The paper's processing of one stereo pair, from what is observed only.

A :class:`PairProcessor` is built from the calibrated cameras, tie points and the 10 frame marks
measured in the two photographs (SIFT; template + weighted centroid, :mod:`kitegully.stereo.measure`)
and the marks' surveyed coordinates: relative orientation on the ties, epipolar rectification,
absolute orientation (similarity) on the marks, then DEMs by epipolar matching
(:mod:`kitegully.stereo.matching`). It never reads the twin's truth.
"""

from __future__ import annotations

import copy
from typing import TYPE_CHECKING, Mapping

import numpy as np

from kitegully import InputError
from kitegully.georef.similarity import umeyama
from kitegully.stereo.matching import MatchParams, disparity_to_points, grid_dem, match_epipolar, triangulate_points
from kitegully.stereo.measure import coplanarity_residuals_px, locate_marks, predict_marks, sift_tie_points
from kitegully.stereo.rectify import rectify_pair, relative_orientation, relative_orientation_from_poses
from kitegully.stereo.rig import look_at_pose
from kitegully.twin.camera import Camera, Pose

if TYPE_CHECKING:
    from kitegully.io.raster import GridSpec, Raster
    from kitegully.stereo.matching import Disparity
    from kitegully.stereo.measure import MarkMeasurement

# [I] Margin of the disparity search beyond the tie points' range (px): a coarse pyramid level's step
# plus the relief between tie points; also the largest step between a tie and its neighbours that is
# still taken for the surface.
DISPARITY_MARGIN_PX = 10.0
# [I] Neighbours a tie's disparity is compared with: enough for a robust median (a false match among
# them is outvoted), few enough to stay local at the ties' spacing (a few mm on the box).
TIE_NEIGHBOURS = 8


def surface_consistent(uv: np.ndarray, disparity: np.ndarray, max_step_px: float, k: int = TIE_NEIGHBOURS) -> np.ndarray:
    """Which tie points lie on the surface their neighbours describe (mask).

    A false match along an epipolar line satisfies the coplanarity condition, so the relative
    orientation keeps it, but its disparity is unlike that of the ties around it: the soil surface is
    continuous at the ties' spacing. A tie is kept when its disparity is within ``max_step_px`` of the
    median of its ``k`` nearest neighbours (rectified image positions).

    Parameters
    ----------
    uv : ndarray (N, 2)
        Rectified left-image positions of the ties (px).
    disparity : ndarray (N,)
        Their disparities (px).
    max_step_px : float
        Largest accepted difference to the neighbours' median (px).
    k : int
        Neighbours compared with.

    Returns
    -------
    ndarray of bool (N,)
        True for ties kept. With fewer than ``k + 1`` ties every tie is kept.

    Notes
    -----
    Cost: O(N log N) (k-d tree).
    """
    from scipy.spatial import cKDTree

    d = np.asarray(disparity, float)
    if d.size <= k:
        return np.ones(d.size, bool)
    _, idx = cKDTree(np.asarray(uv, float)).query(uv, k=k + 1)
    return np.abs(d - np.median(d[idx[:, 1:]], axis=1)) <= max_step_px


class PairProcessor:
    """The paper's processing of one set-up: relative orientation, rectification, absolute orientation, DEMs.

    Built from what is observed: the calibrated cameras, tie points measured in both images
    (pixels), the 10 frame marks measured in both images and their surveyed coordinates,
    the base length and the nominal height. :meth:`from_images` measures the tie points and
    the marks in the photographs themselves; the constructor takes measured positions.

    Attributes
    ----------
    info : dict
        What the measurement gave: ``ties_matched`` (SIFT matches passing the ratio test),
        ``ties_inliers`` (kept by the coplanarity RANSAC), ``tie_sampson_rms_px`` (RMS Sampson
        distance of the inliers to the adjusted coplanarity condition ≈ their per-coordinate
        precision), ``mark_abs_rms_mm`` (RMS 3-D residual of the similarity on the marks),
        ``marks_uv`` (left and right positions) and ``mark_sigma_noise_px`` (median centroid
        precision from the image noise) when measured in images.
    """

    def __init__(self, cams: Mapping[str, Camera], tie_l, tie_r, marks_l, marks_r, marks_xyz, B_m: float, H_m: float,
                 match: MatchParams, centre=(0.0, 0.0)):
        tie_l, tie_r = np.asarray(tie_l, float), np.asarray(tie_r, float)
        # approximate values: the rig's nominal set-up (base B along x at height H, both cameras aimed at the box)
        nl, nr = (look_at_pose(np.array([centre[0] + sx, centre[1], H_m]), np.array([centre[0], centre[1], 0.0]))
                  for sx in (-0.5 * B_m, 0.5 * B_m))
        R, T, inl = relative_orientation(cams["left"], cams["right"], tie_l, tie_r, B_m,
                                         approx=relative_orientation_from_poses(nl, nr))
        if inl.sum() < 8:
            raise InputError(f"relative orientation: only {int(inl.sum())} of {len(inl)} tie points agree with one coplanarity "
                             "condition; at least 8 are needed")
        res = coplanarity_residuals_px(cams["left"], cams["right"], R, T, tie_l[inl], tie_r[inl])
        self.rect = rectify_pair(cams["left"], cams["right"], R, T, (H_m - 0.3, H_m + 0.3))
        self.model_pose = Pose(np.eye(3), np.zeros(3))
        self.marks_xyz = np.asarray(marks_xyz, float)
        self.to_world, abs_rms = self._absolute(marks_l, marks_r)
        rl = self.rect.rectify_points(tie_l[inl], "left")
        dt = rl[:, 0] - self.rect.rectify_points(tie_r[inl], "right")[:, 0]
        dt = dt[surface_consistent(rl, dt, DISPARITY_MARGIN_PX)]
        # [I] the search range is the surface's tie disparities ± 10 px, never wider than the depth range
        # H ± 0.3 m given to the rectification
        lo, hi = sorted(np.ravel(self.rect.disparity_for_depth(np.array([H_m + 0.3, H_m - 0.3]))))
        m = DISPARITY_MARGIN_PX
        self.d_range = (float(max(dt.min() - m, lo)), float(min(dt.max() + m, hi))) if dt.size else (float(lo), float(hi))
        self.cams = cams
        self.match = match
        self.B_m, self.H_m = float(B_m), float(H_m)
        self.info = {"ties_matched": int(len(inl)), "ties_inliers": int(inl.sum()),
                     "tie_sampson_rms_px": float(np.sqrt(np.mean(res ** 2))), "mark_abs_rms_mm": abs_rms}

    def _absolute(self, marks_l, marks_r):
        """Similarity model → world on the frame marks, and the RMS of its 3-D residuals (mm)."""
        ml, mr = self.rect.rectify_points(marks_l, "left"), self.rect.rectify_points(marks_r, "right")
        P = triangulate_points(self.rect, ml, mr, self.model_pose)
        sim = umeyama(P, self.marks_xyz)
        return sim, 1e3 * float(np.sqrt(np.mean(np.sum((sim.apply(P) - self.marks_xyz) ** 2, axis=1))))

    @staticmethod
    def measure_marks(cams: Mapping[str, Camera], img_l: np.ndarray, img_r: np.ndarray, marks_xyz: np.ndarray,
                      diameter_m: float, B_m: float, H_m: float,
                      centre: tuple[float, float] = (0.0, 0.0)) -> list[MarkMeasurement]:
        """Locate the printed marks in both photographs, predicted from the rig's nominal pose (H, B, aimed at ``centre``).

        Parameters
        ----------
        cams : mapping
            Calibrated ``left`` and ``right`` cameras.
        img_l, img_r : ndarray
            The photographs (0–255, NaN = no data).
        marks_xyz : ndarray (N, 3)
            Surveyed coordinates of the marks (m).
        diameter_m : float
            Printed disc diameter (m).
        B_m, H_m : float
            Nominal base and height of the rig (m).
        centre : (float, float)
            Point the rig is aimed at (m).

        Returns
        -------
        list of MarkMeasurement
            The marks in the left image, then in the right image.
        """
        cx, cy = centre
        out = []
        for side, img, sx in (("left", img_l, -0.5 * B_m), ("right", img_r, 0.5 * B_m)):
            nominal = look_at_pose(np.array([cx + sx, cy, H_m]), np.array([cx, cy, 0.0]))
            uv, r = predict_marks(cams[side], nominal, marks_xyz, diameter_m)
            out.append(locate_marks(img, uv, r, side))
        return out

    @classmethod
    def from_images(cls, cams: Mapping[str, Camera], img_l: np.ndarray, img_r: np.ndarray, marks_xyz: np.ndarray,
                    diameter_m: float, B_m: float, H_m: float, match: MatchParams,
                    centre: tuple[float, float] = (0.0, 0.0)) -> "PairProcessor":
        """Measure SIFT tie points and the printed frame marks in a pair of photographs and orient it.

        Parameters
        ----------
        cams : mapping
            Calibrated ``left`` and ``right`` cameras.
        img_l, img_r : ndarray
            The photographs (0–255, NaN = no data).
        marks_xyz : ndarray (N, 3)
            Surveyed coordinates of the marks (m).
        diameter_m : float
            Printed disc diameter (m), for the template and the centroid window.
        B_m, H_m : float
            Nominal base and height of the rig (m).
        match : MatchParams
        centre : (float, float)
            Point the rig is aimed at (m).

        Returns
        -------
        PairProcessor
        """
        tl, tr = sift_tie_points(img_l, img_r)
        ml, mr = cls.measure_marks(cams, img_l, img_r, marks_xyz, diameter_m, B_m, H_m, centre)
        pp = cls(cams, tl, tr, ml.uv, mr.uv, marks_xyz, B_m, H_m, match, centre)
        pp.diameter_m, pp.centre = float(diameter_m), centre
        pp.info.update(marks_uv=(ml.uv, mr.uv), mark_sigma_noise_px=float(np.median(np.r_[ml.sigma_px, mr.sigma_px])))
        return pp

    def reoriented(self, marks_l: np.ndarray, marks_r: np.ndarray) -> "PairProcessor":
        """A copy whose absolute orientation comes from a new image measurement of the frame marks (same survey)."""
        new = copy.copy(self)
        new.to_world, abs_rms = self._absolute(marks_l, marks_r)
        new.info = dict(self.info, mark_abs_rms_mm=abs_rms, marks_uv=(np.asarray(marks_l), np.asarray(marks_r)))
        return new

    def reoriented_from_images(self, img_l: np.ndarray, img_r: np.ndarray) -> "PairProcessor":
        """A copy oriented on the frame marks located anew in this pair's photographs (same relative orientation)."""
        ml, mr = self.measure_marks(self.cams, img_l, img_r, self.marks_xyz, self.diameter_m, self.B_m, self.H_m, self.centre)
        new = self.reoriented(ml.uv, mr.uv)
        new.info["mark_sigma_noise_px"] = float(np.median(np.r_[ml.sigma_px, mr.sigma_px]))
        return new

    def points(self, uv_l: np.ndarray, uv_r: np.ndarray) -> np.ndarray:
        """World coordinates of manually matched points (point measurement)."""
        a, b = self.rect.rectify_points(uv_l, "left"), self.rect.rectify_points(uv_r, "right")
        return self.to_world.apply(triangulate_points(self.rect, a, b, self.model_pose))

    def dem(self, img_l: np.ndarray, img_r: np.ndarray, grid: GridSpec, z_range: tuple[float, float] = (-0.05, 0.05),
            return_disparity: bool = False) -> tuple[Raster, int] | tuple[Raster, int, Disparity]:
        """Surface measurement: match the rectified pair where it sees ``grid``, triangulate, grid (mean per cell).

        Only the part of the left rectified image that sees the grid (between ``z_range``, world m)
        is matched: the frame and the walls are not part of the DEM. Returns ``(dem, matched pixels)``,
        and the :class:`Disparity` as a third item with ``return_disparity``.

        Parameters
        ----------
        img_l, img_r : ndarray
            The photographs (0–255, NaN = no data).
        grid : GridSpec
            The DEM grid.
        z_range : (float, float)
            Lowest and highest elevation the grid's surface may have (world, m); sets the matched part of the image.
        return_disparity : bool
            Also return the disparity.

        Returns
        -------
        dem : Raster
            Mean elevation per cell (m), NaN where fewer than 3 points fall.
        matched : int
            Number of matched pixels.
        disparity : Disparity
            Only with ``return_disparity``.
        """
        Lr, Rr = self.rect.remap(img_l, "left"), self.rect.remap(img_r, "right")
        x0, y0, x1, y1 = self._roi(grid, z_range, Lr.shape)
        levels = int(np.clip(np.ceil(np.log2(max(self.d_range[1] - self.d_range[0], 8) / 8)), 2, 5))
        disp = match_epipolar(Lr, Rr, self.d_range, MatchParams(levels=levels, **{k: v for k, v in self.match.__dict__.items() if k != "levels"}),
                              roi=(x0, y0, x1, y1))
        P = self.to_world.apply(disparity_to_points(disp, self.rect, self.model_pose))
        if return_disparity:
            return grid_dem(P, grid, min_count=3), int(disp.valid.sum()), disp
        return grid_dem(P, grid, min_count=3), int(disp.valid.sum())

    def _roi(self, grid: GridSpec, z_range, shape, margin_px: int = 96) -> tuple[int, int, int, int]:
        """Bounding box (px) in the left rectified image of the grid's corners at both ends of ``z_range``.

        [I] The margin (96 px) is a coarse-level matching window (11 px at level 3 = 88 px): near the
        edge of the matched region the coarse levels see no data and the fine levels inherit blunders.
        """
        x0, y0, x1, y1 = grid.bounds
        W = np.array([[x, y, z] for x in (x0, x1) for y in (y0, y1) for z in z_range], float)
        s = self.to_world
        Xm = ((W - s.t) @ s.R) / s.scale  # world -> model (= left camera) frame
        Xr = Xm @ self.rect.R1.T
        uv = (Xr @ self.rect.P1[:, :3].T + self.rect.P1[:, 3])
        uv = uv[:, :2] / uv[:, 2:3]
        h, w = shape
        return (max(0, int(uv[:, 0].min()) - margin_px), max(0, int(uv[:, 1].min()) - margin_px),
                min(w, int(uv[:, 0].max()) + margin_px), min(h, int(uv[:, 1].max()) + margin_px))

