"""The ``stereo`` stage: the paper's lab runs on a stereo-rig twin (Moritani et al. 2010, issue 19).

Entry points, one per rule, named after what they make:

* :func:`calibrate_rig` — Table 1 regenerated (``calibration.csv``) and the calibration test
  (H = 2–6 m, B = 1.0 m, with and without inner orientation, ``calibration_test.csv`` + figure);
  writes the calibrated cameras (JSON) that every later run processes with.
* :func:`measure_dry_box` — 11 set-ups (point and surface MAE vs L, both fits and the δz
  model line) and the 16 removals at L = 9.1 m (``A = b·M``).
* :func:`measure_rain` — the three bulk densities under 60 mm/h for 1 h on 10°.
* :func:`measure_wind` — the wind-tunnel tray, before/after.

Every pair is made in two separate steps: a *twin* step renders the two photographs of
the true surface through the true cameras (:func:`_render_pair`), and a *processing* step
sees only what the paper had — the photographs, the calibrated cameras and the surveyed
coordinates of the 10 printed frame marks — measures tie points (SIFT) and the marks
(template + weighted centroid, :mod:`kitegully.stereo.measure`) in the photographs and returns
a DEM (:class:`PairProcessor.from_images`).
Only the evaluation (MAE against the point gauge or the gravimetric depth) reads the
reference, as the paper's did.
"""

from __future__ import annotations

import json
import logging
import time
from dataclasses import dataclass
from typing import ClassVar
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Mapping

import numpy as np
import pandas as pd

from kitegully import InputError
from kitegully.config import config_section
from kitegully.evaluate.dem import nmad
from kitegully.georef.similarity import umeyama
from kitegully.io.figures import new_figure, save_figure
from kitegully.io.raster import GridSpec
from kitegully.io.tables import write_table
from kitegully.seeds import rng_for
from kitegully.stereo.calibration import (ControlField, calibrate_camera, calibrate_camera_weighted, calibration_field,
                                          calibration_poses, calibration_table, convergent_poses, distortion_precision,
                                          measure_calibration_images,
                                          simulate_observations)
from kitegully.stereo.matching import MatchParams, disparity_to_points, grid_dem, match_epipolar, triangulate_points
from kitegully.stereo.metrics import fit_A_vs_M, fit_mae_vs_L, mae, mre
from kitegully.stereo.rectify import rectify_pair, relative_orientation, relative_orientation_from_poses
from kitegully.stereo.measure import (MarkDesign, PrintedMarks, coplanarity_residuals_px, locate_marks, predict_marks,
                                      sift_tie_points)
from kitegully.stereo.rig import (D2H_NOMINAL_F_MM, D2H_PIXEL_MM, StereoRig, delta_z_m, look_at_pose, paper_cameras, paper_rig,
                                  stereo_L_m)
from kitegully.stereo.synth import render_heightfield, soil_texture
from kitegully.twin.camera import Camera, Pose

if TYPE_CHECKING:
    from kitegully.io.raster import Raster
    from kitegully.stereo.matching import Disparity
    from kitegully.stereo.measure import MarkMeasurement
    from kitegully.stereo.rectify import Rectification

log = logging.getLogger(__name__)

#: Matching precision (px) of the LoG coarse-to-fine matcher on the rendered soil, measured against the
#: ray-cast true disparity by benchmarks/stereo_benchmark.py (0.043-0.050 px over L = 5.8-35 m; 0.046 at 9.1 m).
MATCHING_PRECISION_PX = 0.046

PAPER = {"a_calibration_without_io": 0.74, "a_calibration_with_io": 0.057, "a_point": 0.049, "a_surface": 0.030,
         "b": 1.06, "mae_9_1_mm": 0.21, "mre_9_1_pct": 15.8, "wind_mae_mm": 0.21, "upstream_minus_downstream_mm": 0.49,
         "rain": {0.91: (2.21, 392.5), 0.98: (1.07, 126.4), 1.09: (0.59, 57.6)}}


# ----------------------------------------------------------------------------- parameters
def _floats(v, where: str, n: int | None = None) -> tuple[float, ...]:
    try:
        out = tuple(float(x) for x in v)
    except (TypeError, ValueError):
        raise InputError(f"{where}: must be a list of numbers, got {v!r}") from None
    if n is not None and len(out) != n:
        raise InputError(f"{where}: must hold {n} numbers, got {len(out)}")
    return out


def _positive(where: str, **vals: float) -> None:
    for k, v in vals.items():
        if not (v > 0):
            raise InputError(f"{where}.{k}: must be positive, got {v}")


#: Calibration image sets (``stereo.calibration.stations``).
STATIONS = ("paper", "paper+convergent", "paper+convergent+corners")


@dataclass(frozen=True)
class StereoParams:
    """Parameters of the stereo stage (config section ``stereo``; keys as below, nested).

    Attributes
    ----------
    calibration.stations : str
        ``"paper"`` = the paper's 6 parallel images shifted over the field at H ≈ 3 m;
        ``"paper+convergent"`` = those 6 plus ``n_convergent`` convergent, rolled images;
        ``"paper+convergent+corners"`` = those 14 plus ``n_corner`` convergent images turned
        so the field's centre is imaged ``corner_fraction`` of the way to a frame corner.
        [I] see :func:`kitegully.stereo.calibration.convergent_poses`: near-nadir images
        cannot separate f from the camera distance against a 0.2 mm field error, and K1 is
        only told from K2 where targets reach the frame's corners.
    calibration.n_corner, calibration.corner_fraction : int, float
        The corner images (optional; default 8 and 0.5).
    calibration.weighted_control : bool
        Adjust the field coordinates as observations with σ = ``field_sigma_mm``
        (free network with weighted control) instead of holding them fixed.
    calibration.H_m : float
        Height of the calibration images (m) [P] ≈ 3.0.
    calibration.target_sigma_px : float
        Target measurement precision (px). [I] 0.1 px: centroids of round targets ~10 px wide.
    calibration.targets : str
        ``"rendered"``: each target a printed disc rendered into the photographs and located
        (template + weighted centroid, :func:`kitegully.stereo.calibration.measure_targets`), the
        bundle weighted with the median centroid σ from the noise; ``"simulated"``: projections +
        N(0, ``target_sigma_px``) (the session-9 model; the calibration test at H = 2–6 m always uses it).
    calibration.target_diameter_mm, calibration.image_noise_dn : float
        Printed disc (mm) [I] 10: 15–18 px across at 3.0–3.6 m (see ``TARGET_DIAMETER_M``); image noise (DN) [I] 1.
    calibration.field_sigma_mm : float
        Accuracy of the field coordinates (mm) [P] 0.2.
    calibration.convergent_offset_m, calibration.n_convergent : float, int
        Radius of the circle of convergent stations (m) and their number.
    calibration_test.H_m, calibration_test.B_m : list of float, float
        [P] 5 heights 2.0–6.0 m at B = 1.0 m.
    processing.image_noise_dn : float
        Image noise (DN of 255) [I] 1 DN, a well exposed 12-bit raw scaled to 8 bit.
    processing.mark_diameter_mm : float
        Diameter of the printed white disc of each frame mark (on a black plate 2.4 × as wide,
        :class:`kitegully.stereo.measure.MarkDesign`). [I] 10 mm: ≥ 10 px across at the highest
        set-up (11.6 px at H 4.7 m, 0.86 mm ground pixel), enough for a centroid of every pixel
        of the disc (close-range practice asks for ≥ 5 px). Tie points and marks are measured in
        the photographs (SIFT; template + weighted centroid); their precision is what the images give.
    processing.mark_sigma_mm : float
        Accuracy of the surveyed frame-mark coordinates (mm). [I] 0.1 mm.
    processing.manual_sigma_px : float
        Precision of manual point matching of a nail head (px). [I] 0.3 px.
    processing.reorient_each_pair : bool
        Orient every pair of a series (removals, rain epochs) on its own measurement of the
        10 frame marks (True) or reuse the first pair's absolute orientation (False). [I] True:
        each DEM of the paper is made on its own, so its orientation errors (offset and tilt,
        ∝ L like the matching's) do not cancel in a DEM of difference.
    processing.cell_mm : float
        DEM cell (mm). [I] 5 mm: ~10 × 10 matched pixels per cell at L = 9.1 m.
    processing.matching : mapping
        :class:`kitegully.stereo.matching.MatchParams` keys (window_px, search_px, min_ncc, sigma_px).
    dry_box.setups : list of [H, B]
        The 11 set-ups (m) [P] H 2.4–4.7, B 0.3–1.0 (L 5–35 m); [I] the pairs themselves.
    dry_box.removals, dry_box.removal_ml, dry_box.bulk_density : int, float, float
        [P] 16 removals; [I] 50 mL each (METHODS 4.6); [P] ρ_b 1.09 g/cm³ (Table 2).
    dry_box.removal_H_m, dry_box.removal_B_m : float
        Geometry of the removals [P] L = 9.1 m (H 2.7, B 0.8).
    rain.bulk_densities : list of float
        [P] 0.91 / 0.98 / 1.09 g/cm³.
    rain.intensity_mm_h, rain.duration_min, rain.slope_deg, rain.H_m, rain.B_m, rain.interval_min : float
        [P] 60 mm/h, 60 min, 10°, H 2.7 m, B 0.8 m; [I] a pair every 10 min.
    rain.interrill_erodibility : float
        WEPP interrill erodibility K_i (kg·s/m⁴) in ``D_i = K_i·I²·S_f``. [I] 1.0e6, the
        low end of WEPP's range for clay soils (56 % clay, Table 2); the same for all densities.
    rain.seal_depth_mm, rain.seal_density : float
        Settlement model [I]: rain compacts the top ``seal_depth_mm`` from ρ_b to
        ``seal_density`` (g/cm³), exponentially with time constant ``settle_min``, so the
        settlement per density is ``s = d·(1 − ρ_b/ρ_seal)`` (stated in rain_runs.csv).
        [I] 10 mm (raindrop compaction and slaking reach a few mm to ~1 cm) and 1.20 g/cm³
        (a sealed clay crust is denser than the densest packed box, 1.09). Not fitted to the paper.
    rain.settle_min : float
        Time constant of the settlement (min). [I] 15 min (most of the slaking happens early).
    rain.ksat_mm_h, rain.manning_n, rain.rill_erodibility_s_m, rain.critical_shear_pa : float
        Runoff-accumulation model along the slope (:func:`runoff_detachment_kg_m2_h`): sheet flow
        ``q(y) = (I − Ksat)·y`` from the upslope wall, Manning depth, shear ``τ = ρ g h sin θ``,
        WEPP flow detachment ``D_f = K_r (τ − τ_c)`` added to the uniform interrill rate.
        [P] Ksat 6.7e-5 cm/s = 2.41 mm/h (Table 2); [I] n = 0.03 (bare smoothed soil);
        [I] WEPP baseline for soils with < 30 % sand (Table 2: 22 %): K_r = 0.0069 + 0.134·exp(−20·clay)
        = 0.0069 s/m at 56 % clay, τ_c = 3.5 Pa. Not fitted to the paper's 0.49 mm.
    wind.H_m, wind.B_m, wind.duration_min : float
        [P] H 0.6 m, B 0.3 m, 45 min.
    wind.deflation_mm, wind.ripple_mm, wind.ripple_wavelength_mm, wind.sand_density : float
        [I] Mean deflation 1.0 mm over 45 min at 4.5 m/s (a few g per cm of width per
        minute for fine sand just above threshold), ripples 1 mm high, 12 mm long, migrating
        half a wavelength; sand ρ_b 1.5 g/cm³.
    wind.cell_mm : float
        DEM cell of the tray (mm). [I] 2 mm: the ground pixel is 0.11 mm at H = 0.6 m.
    wind.mark_diameter_mm : float
        Disc diameter of the tray's frame marks (mm). [I] 2 mm: 18 px at H 0.6 m (0.11 mm ground
        pixel), and the marks with their plates stay inside both frames, which span only ±0.09 m
        across the base at that height.
    """

    calibration: Mapping[str, Any]
    calibration_test: Mapping[str, Any]
    processing: Mapping[str, Any]
    dry_box: Mapping[str, Any]
    rain: Mapping[str, Any]
    wind: Mapping[str, Any]

    KEYS = {
        "calibration": ("stations", "weighted_control", "H_m", "target_sigma_px", "field_sigma_mm", "convergent_offset_m", "n_convergent"),
        "calibration_test": ("H_m", "B_m"),
        "processing": ("image_noise_dn", "mark_diameter_mm", "mark_sigma_mm", "manual_sigma_px", "reorient_each_pair",
                       "cell_mm", "matching"),
        "dry_box": ("setups", "removals", "removal_ml", "bulk_density", "removal_H_m", "removal_B_m"),
        "rain": ("bulk_densities", "intensity_mm_h", "duration_min", "interval_min", "slope_deg", "H_m", "B_m",
                 "interrill_erodibility", "seal_depth_mm", "seal_density", "settle_min", "ksat_mm_h", "manning_n",
                 "rill_erodibility_s_m", "critical_shear_pa"),
        "wind": ("H_m", "B_m", "duration_min", "deflation_mm", "ripple_mm", "ripple_wavelength_mm", "sand_density", "cell_mm",
                 "mark_diameter_mm"),
    }

    #: optional keys (default: targets simulated)
    OPTIONAL: ClassVar[dict] = {"calibration": ("targets", "target_diameter_mm", "image_noise_dn", "n_corner", "corner_fraction")}

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any]) -> "StereoParams":
        """Build from the ``stereo`` section or any subset of its sub-sections (a rule passes only what it uses)."""
        config_section(cfg, "stereo", (), optional=cls.KEYS)
        out = {}
        for sec, keys in cls.KEYS.items():
            if sec not in cfg:
                out[sec] = {}
                continue
            c = dict(config_section(cfg[sec], f"stereo.{sec}", keys, cls.OPTIONAL.get(sec, ())))
            out[sec] = c
        p = cls(**out)
        p._validate()
        return p

    def _validate(self) -> None:
        c = self.calibration
        if c:
            if c["stations"] not in STATIONS:
                raise InputError(f"stereo.calibration.stations: must be one of {', '.join(STATIONS)}, got {c['stations']!r}")
            if not 0.0 <= float(c.get("corner_fraction", 0.5)) < 1.0:
                raise InputError(f"stereo.calibration.corner_fraction: must be in [0, 1), got {c['corner_fraction']!r}")
            _positive("stereo.calibration", H_m=c["H_m"], target_sigma_px=c["target_sigma_px"], field_sigma_mm=c["field_sigma_mm"])
        if self.calibration_test:
            _floats(self.calibration_test["H_m"], "stereo.calibration_test.H_m")
        if self.processing:
            MatchParams(**self.processing["matching"])
            _positive("stereo.processing", cell_mm=self.processing["cell_mm"], mark_diameter_mm=self.processing["mark_diameter_mm"])
        if self.dry_box:
            for s in self.dry_box["setups"]:
                H, B = _floats(s, "stereo.dry_box.setups item", 2)
                _positive("stereo.dry_box.setups", H_m=H, B_m=B)
        if self.rain:
            for rho in _floats(self.rain["bulk_densities"], "stereo.rain.bulk_densities"):
                if not 0 < rho < self.rain["seal_density"]:
                    raise InputError(f"stereo.rain.bulk_densities: {rho} g/cm³ must lie between 0 and seal_density "
                                     f"({self.rain['seal_density']}), or the soil would swell under rain")


# ----------------------------------------------------------------------------- twin: surfaces and rendering
BOX = (-0.15, -0.25, 0.15, 0.25)  # 0.30 (x, along the base) × 0.50 m (y)
TEXTURE_EXTENT = (-0.2, -0.3, 0.2, 0.3)  # box, frame and marks


def _relief(x, y):
    """Dry-box soil surface: a few millimetres of clods and rills (m)."""
    return 0.004 * np.sin(2 * np.pi * x / 0.12) * np.cos(2 * np.pi * y / 0.2) + 0.002 * np.sin(2 * np.pi * (x + y) / 0.05)


def _frame_marks(box=BOX) -> np.ndarray:
    """The 10 absolute-orientation marks on the box frame (m), 2 cm outside the soil, 1 cm above it.

    Six at the corners and the middle of the long sides, four on the short sides at ±0.2 of the
    box length from its middle (±0.1 m on the 0.5 m box).
    """
    x0, y0, x1, y1 = box
    yc, dy = 0.5 * (y0 + y1), 0.2 * (y1 - y0)
    return np.array([[x, y, 0.01] for x in (x0 - 0.02, 0.5 * (x0 + x1), x1 + 0.02) for y in (y0 - 0.02, y1 + 0.02)]
                    + [[x0 - 0.02, y, 0.01] for y in (yc - dy, yc + dy)] + [[x1 + 0.02, y, 0.01] for y in (yc - dy, yc + dy)])


def _nails(rng: np.random.Generator, box=BOX, n: int = 20) -> np.ndarray:
    """Nail heads (x, y) on a 4 × 5 grid in the central part of the box, jittered by 5 mm."""
    x0, y0, x1, y1 = box
    xs = np.linspace(x0, x1, 6)[1:-1]
    ys = np.linspace(y0, y1, 7)[1:-1]
    X, Y = np.meshgrid(xs, ys)
    return np.column_stack([X.ravel(), Y.ravel()])[:n] + rng.normal(0, 0.005, (n, 2))


def _window(cam: Camera, pose: Pose, pts: np.ndarray, margin_px: int = 160) -> tuple[int, int, int, int]:
    uv = cam.project(pts, pose)
    return (int(np.nanmin(uv[:, 0])) - margin_px, int(np.nanmin(uv[:, 1])) - margin_px,
            int(np.nanmax(uv[:, 0])) + margin_px, int(np.nanmax(uv[:, 1])) + margin_px)


def _render_pair(rig: StereoRig, height: Callable, texture, noise_dn: float, rng, extent_pts: np.ndarray, marks: PrintedMarks):
    """Twin step: the two photographs of ``height`` with the printed frame marks on their plates.

    Only the window that sees ``extent_pts`` and the mark plates is rendered.
    """
    ext = np.vstack([extent_pts, marks.corners()])
    wl = _window(rig.left, rig.pose_left, ext)
    wr = _window(rig.right, rig.pose_right, ext)
    # [I] 5 fixed-point iterations: the ray-surface error shrinks by ~slope·tan(view angle) < 0.1 per iteration
    L = render_heightfield(rig.left, rig.pose_left, height, texture, iterations=5, noise_dn=noise_dn, rng=rng, window=wl, marks=marks)
    R = render_heightfield(rig.right, rig.pose_right, height, texture, iterations=5, noise_dn=noise_dn, rng=rng, window=wr, marks=marks)
    return L, R


# ----------------------------------------------------------------------------- processing (observed data only)
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
        import copy

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


def _survey(marks_xyz: np.ndarray, rng, proc: Mapping[str, Any]) -> np.ndarray:
    """Twin step: the surveyed coordinates of the frame marks (true + N(0, ``mark_sigma_mm``) per coordinate)."""
    return marks_xyz + rng.normal(0, proc["mark_sigma_mm"] * 1e-3, marks_xyz.shape)


def mark_error_px(pp: "PairProcessor", truth: StereoRig, marks_xyz: np.ndarray) -> float:
    """Evaluation: RMS (px, per coordinate, both images) of the located marks minus their true projections.

    Parameters
    ----------
    pp : PairProcessor
        Pair built from images; ``info["marks_uv"]`` holds the located marks.
    truth : StereoRig
        The true cameras and poses.
    marks_xyz : ndarray (N, 3)
        True coordinates of the marks (m).

    Returns
    -------
    float
        RMS error (px).
    """
    ml, mr = pp.info["marks_uv"]
    e = np.r_[ml - truth.left.project(marks_xyz, truth.pose_left), mr - truth.right.project(marks_xyz, truth.pose_right)]
    return float(np.sqrt(np.mean(e ** 2)))


def _pair_columns(pp: "PairProcessor", truth: StereoRig, marks_xyz: np.ndarray) -> dict[str, float]:
    """The measurement columns of one pair: ties, mark precision from the noise, residuals, error against the truth."""
    i = pp.info
    return {"ties_matched": i["ties_matched"], "ties_inliers": i["ties_inliers"], "tie_sampson_rms_px": i["tie_sampson_rms_px"],
            "mark_sigma_noise_px": i["mark_sigma_noise_px"], "mark_abs_rms_mm": i["mark_abs_rms_mm"],
            "mark_error_px": mark_error_px(pp, truth, marks_xyz)}


def matching_residual_px(rect: Rectification, disp: Disparity, truth: StereoRig, height: Callable, grid: GridSpec,
                         step_m: float = 0.002) -> dict[str, float]:
    """Evaluation: the matcher's achieved precision δ (px), measured directly against the twin's surface.

    Points of the true surface (every ``step_m`` over ``grid``) are projected through the true
    cameras into both photographs and mapped into the *processing's* rectified images; the
    matched disparity at the left position (bilinear, only where all four neighbours matched)
    minus ``x_l − x_r`` of those positions is the matching error. It is independent of the
    calibration and orientation errors (they move both the matched and the true positions
    alike), so it is the δ of the paper's Eq. 1 as this matcher achieves it on these images.

    Parameters
    ----------
    rect : Rectification
        The processing's rectification (estimated cameras and relative orientation).
    disp : Disparity
        The matched disparity of the left rectified image.
    truth : StereoRig
        The twin's true cameras and poses (evaluation only).
    height : callable
        True surface ``z = h(x, y)`` (m).
    grid : GridSpec
        Area to sample (the DEM's grid).
    step_m : float
        Sample spacing (m).

    Returns
    -------
    dict
        ``sigma_d_px`` (1.4826·MAD), ``bias_d_px`` (median), ``y_parallax_rms_px`` (RMS of
        ``y_l − y_r`` of the true points: the rectification's residual vertical parallax) and
        ``n`` (samples).

    Notes
    -----
    Cost: O(samples).
    """
    from scipy.ndimage import map_coordinates

    x0, y0, x1, y1 = grid.bounds
    X, Y = np.meshgrid(np.arange(x0 + step_m / 2, x1, step_m), np.arange(y0 + step_m / 2, y1, step_m))
    P = np.column_stack([X.ravel(), Y.ravel(), height(X.ravel(), Y.ravel())])
    a = rect.rectify_points(truth.left.project(P, truth.pose_left), "left")
    b = rect.rectify_points(truth.right.project(P, truth.pose_right), "right")
    d = np.where(disp.valid, disp.d, 0.0)
    coords = np.vstack([a[:, 1], a[:, 0]])
    dm = map_coordinates(d, coords, order=1, mode="constant", cval=np.nan)
    ok4 = map_coordinates(disp.valid.astype(float), coords, order=1, mode="constant", cval=0.0) > 0.999
    err = (dm - (a[:, 0] - b[:, 0]))[ok4]
    if err.size < 10:
        return {"sigma_d_px": float("nan"), "bias_d_px": float("nan"), "y_parallax_rms_px": float("nan"), "n": int(err.size)}
    med = float(np.median(err))
    return {"sigma_d_px": nmad(err), "bias_d_px": med,
            "y_parallax_rms_px": float(np.sqrt(np.mean((a[:, 1] - b[:, 1]) ** 2))), "n": int(err.size)}


def error_decomposition(dem: np.ndarray, ref: np.ndarray, grid: GridSpec) -> dict[str, float]:
    """Split a DEM's error into a plane (orientation-type: offset and tilt) and the rest (matching-type).

    Parameters
    ----------
    dem, ref : ndarray
        DEM and reference surface on ``grid`` (m); NaN in ``dem`` = no data.
    grid : GridSpec
        Their grid.

    Returns
    -------
    dict
        ``mean_error_mm`` (box-mean DEM − reference), ``tilt_mm_per_m`` (gradient magnitude of
        the best-fitting plane of the error), ``plane_mae_mm`` (MAE of that plane alone) and
        ``residual_mae_mm`` (MAE after removing it).
    """
    ok = np.isfinite(dem) & np.isfinite(ref)
    X, Y = np.meshgrid(*grid.cell_centres())
    e = (dem - ref)[ok]
    A = np.column_stack([np.ones(e.size), X[ok] - X[ok].mean(), Y[ok] - Y[ok].mean()])
    c, *_ = np.linalg.lstsq(A, e, rcond=None)
    plane = A @ c
    return {"mean_error_mm": 1e3 * float(e.mean()), "tilt_mm_per_m": 1e3 * float(np.hypot(c[1], c[2])),
            "plane_mae_mm": 1e3 * float(np.mean(np.abs(plane))), "residual_mae_mm": 1e3 * float(np.mean(np.abs(e - plane)))}


def _box_grid(cell_m: float, box=BOX, share: float = 0.8) -> GridSpec:
    """Grid over the central ``share`` of the box area (the walls shade the rest, paper sect. 2)."""
    s = np.sqrt(share)
    nx, ny = int(round((box[2] - box[0]) * s / cell_m)), int(round((box[3] - box[1]) * s / cell_m))
    cx, cy = 0.5 * (box[0] + box[2]), 0.5 * (box[1] + box[3])
    return GridSpec(cx - nx * cell_m / 2, cy + ny * cell_m / 2, cell_m, nx, ny, "EPSG:32632")


def _cell_truth(height: Callable, grid: GridSpec, sub: int = 6) -> np.ndarray:
    """Reference surface per cell (mean of ``height`` over the cell), as a point gauge traverse would give."""
    X, Y = np.meshgrid(*grid.cell_centres())
    off = (np.arange(sub) + 0.5) / sub - 0.5
    return np.mean([height(X + a * grid.cell, Y + b * grid.cell) for a in off for b in off], axis=0)


def _load_cameras(path: str | Path) -> dict[str, Camera]:
    data = json.loads(Path(path).read_text(encoding="utf-8"))
    try:
        return {side: Camera(**data[side]) for side in ("left", "right")}
    except (KeyError, TypeError) as exc:
        raise InputError(f"{path}: not a calibrated stereo camera file (needs 'left' and 'right' cameras): {exc}") from None


def _dod_figure(dod: np.ndarray, grid: GridSpec, title: str, path: str | Path) -> None:
    fig, ax = new_figure(figsize=(4.2, 5.0))
    v = np.nanpercentile(np.abs(dod), 98) if np.isfinite(dod).any() else 1.0
    x0, y0, x1, y1 = grid.bounds
    im = ax.imshow(dod, cmap="RdBu", vmin=-v, vmax=v, extent=(1e3 * x0, 1e3 * x1, 1e3 * y0, 1e3 * y1))
    fig.colorbar(im, ax=ax, label="DEM of difference, after − before (mm)")
    ax.set_xlabel("x along the base (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_title(title)
    save_figure(fig, path, "kitegully stereo twin after Moritani et al. (2010)")


# ----------------------------------------------------------------------------- rule: calibration
#: [I] bound on the prediction error of a target through the nominal 50 mm lens: 2.8 % of f (51.4 vs 50 mm) at the
#: 1480 px half-diagonal = 41 px, + principal point (≤ 10 px) + distortion (≤ 4 px) ≈ 55 px → 60 px.
PREDICTION_ALLOWANCE_PX = 60.0


def _calibrate(cams_true, params: StereoParams, seed: int, stations: str, weighted: bool):
    c = params.calibration
    rng = rng_for(seed, "stereo", "calibration")
    field = calibration_field()
    poses = calibration_poses(H_m=c["H_m"])
    if stations.startswith("paper+convergent"):
        poses = poses + convergent_poses(c["H_m"], c["convergent_offset_m"], int(c["n_convergent"]))
    if stations == "paper+convergent+corners":
        poses = poses + convergent_poses(c["H_m"], c["convergent_offset_m"], int(c.get("n_corner", 8)),
                                         corner_fraction=float(c.get("corner_fraction", 0.5)))
    known = ControlField(field.ids, field.xyz + rng.normal(0.0, c["field_sigma_mm"] * 1e-3, field.xyz.shape))
    out = {}
    for side, cam in cams_true.items():
        sigma = c["target_sigma_px"]
        if c.get("targets", "simulated") == "rendered":
            # targets rendered as printed discs and located in the photographs; predicted through the nominal lens
            nom = _without_io(cam, True, True, True)
            obs, sigma = measure_calibration_images(cam, nom, field, known, poses, c["target_diameter_mm"] * 1e-3, c["image_noise_dn"],
                                                    rng_for(seed, "stereo", "target_images", side), PREDICTION_ALLOWANCE_PX, side)
            log.info("%s: %d targets measured in %d rendered photographs, median centroid σ %.4f px", side,
                     sum(len(o.ids) for o in obs), len(obs), sigma)
        else:
            obs = simulate_observations(cam, field, poses, sigma, rng_for(seed, "stereo", "targets", side))
        if weighted:
            out[side] = calibrate_camera_weighted(known, obs, cam.width, cam.height, D2H_PIXEL_MM, sigma,
                                                  c["field_sigma_mm"] * 1e-3, template=cam, name=side)[0]
        else:
            out[side] = calibrate_camera(known, obs, cam.width, cam.height, D2H_PIXEL_MM, template=cam, name=side)
    return out, field


def _without_io(cam: Camera, nominal_f: bool, no_distortion: bool, centred_pp: bool) -> Camera:
    """The camera as processed without (part of) its inner orientation: nominal 50 mm, no distortion, centred principal point."""
    kw = dict(cam.__dict__)
    if nominal_f:
        kw["f"] = D2H_NOMINAL_F_MM / D2H_PIXEL_MM
    if no_distortion:
        kw["k1"] = kw["k2"] = 0.0
    if centred_pp:
        kw["cx"], kw["cy"] = (cam.width - 1) / 2.0, (cam.height - 1) / 2.0
    return Camera(**kw)


def calibrate_rig(cfg: Mapping[str, Any], seed: int, out: Mapping[str, str]) -> None:
    """Rule ``stereo_calibrate``: Table 1, the calibration test and the calibrated cameras.

    Parameters
    ----------
    cfg : mapping
        ``stereo.calibration``, ``stereo.calibration_test`` and ``stereo.processing``.
    seed : int
        Master seed.
    out : mapping
        Paths ``calibration`` (csv), ``cameras`` (json), ``test`` (csv), ``test_png``.
    """
    params = StereoParams.from_config(cfg)
    t0 = time.perf_counter()
    cams_true = paper_cameras()
    c = params.calibration
    chosen, field = _calibrate(cams_true, params, seed, c["stations"], bool(c["weighted_control"]))
    paper_proto, _ = _calibrate(cams_true, params, seed, "paper", False)
    tab = calibration_table(chosen, cams_true)
    alt = calibration_table(paper_proto, cams_true)
    tab.insert(4, "recovered_paper_protocol", alt["recovered"].to_numpy())
    tab["error_paper_protocol"] = alt["error"].to_numpy()
    tab["rms_px"] = [chosen[s].rms_px for s in tab["camera"]]
    if all(r.covariance is not None for r in chosen.values()):
        # K1 with its standard error, its correlations and the displacement it causes at the frame corner (what a DEM sees)
        prec = {s: distortion_precision(r, cams_true[s]) for s, r in chosen.items()}
        for key in ("K1_se", "corr_K1_K2", "corr_K1_f", "edge_dr_px", "edge_dr_se_px", "edge_dr_err_px", "K1_err_in_se"):
            tab[key] = [prec[s][key] for s in tab["camera"]]
        log.info("calibration: K1 %s", {s: f"{p['K1']:.3g} ± {p['K1_se']:.2g} (truth error {p['K1_err_pct']:+.1f} %, corner Δr error "
                                          f"{p['edge_dr_err_px']:+.3f} ± {p['edge_dr_se_px']:.3f} px)" for s, p in prec.items()})
    tab["method"] = f"{c['stations']} stations, " + ("weighted control" if c["weighted_control"] else "fixed control")
    write_table(tab, out["calibration"])
    cams = {s: r.camera for s, r in chosen.items()}
    Path(out["cameras"]).write_text(json.dumps({s: cam.__dict__ for s, cam in cams.items()}, indent=1), encoding="utf-8")
    log.info("calibration: f errors %s mm", {s: round(float(tab.loc[(tab.camera == s) & (tab.parameter == 'f'), 'error'].iloc[0]), 4) for s in cams})

    # calibration test: the field seen by the rig at 5 heights; processed with and without inner orientation
    ct = params.calibration_test
    nominal = {s: _without_io(cam, True, True, True) for s, cam in cams.items()}
    # [I] ablation: which part of the inner orientation the "without" error comes from (each left out alone)
    variants = [("with inner orientation", cams), ("without inner orientation", nominal),
                ("without: nominal f only", {s: _without_io(cam, True, False, False) for s, cam in cams.items()}),
                ("without: no distortion only", {s: _without_io(cam, False, True, False) for s, cam in cams.items()}),
                ("without: centred principal point only", {s: _without_io(cam, False, False, True) for s, cam in cams.items()})]
    rows = []
    sig = c["target_sigma_px"]
    for H in _floats(ct["H_m"], "stereo.calibration_test.H_m"):
        B = float(ct["B_m"])
        rng = rng_for(seed, "stereo", "calibration_test", f"{H}")
        truth = paper_rig(H, B, centre_xy=(0.0, 0.0))
        ul = truth.left.project(field.xyz, truth.pose_left) + rng.normal(0, sig, (len(field.xyz), 2))
        ur = truth.right.project(field.xyz, truth.pose_right) + rng.normal(0, sig, (len(field.xyz), 2))
        surveyed = field.xyz + rng.normal(0, c["field_sigma_mm"] * 1e-3, field.xyz.shape)
        gcp = np.arange(0, 32, 3)[:10]
        chk = np.setdiff1d(np.arange(32), gcp)
        for label, cset in variants:
            R, T, _ = relative_orientation(cset["left"], cset["right"], ul, ur, B)
            rect = rectify_pair(cset["left"], cset["right"], R, T, (H - 0.5, H + 0.5))
            P = triangulate_points(rect, rect.rectify_points(ul, "left"), rect.rectify_points(ur, "right"), Pose(np.eye(3), np.zeros(3)))
            sim = umeyama(P[gcp], surveyed[gcp])
            err = sim.apply(P[chk]) - field.xyz[chk]
            rows.append({"H_m": H, "B_m": B, "L_m": float(stereo_L_m(H, B)), "processing": label,
                         "mae_z_mm": 1e3 * float(np.mean(np.abs(err[:, 2]))), "mae_3d_mm": 1e3 * float(np.mean(np.linalg.norm(err, axis=1))),
                         "check_points": len(chk)})
    test = pd.DataFrame(rows)
    fits = {}
    for label, g in test.groupby("processing"):
        fits[label] = fit_mae_vs_L(g["L_m"], g["mae_z_mm"])
    test["a_fit_mm_per_m"] = [fits[p][0] for p in test["processing"]]
    test["r2_fit"] = [fits[p][1] for p in test["processing"]]
    test["a_paper_mm_per_m"] = [PAPER["a_calibration_with_io"] if p.startswith("with ") else
                                PAPER["a_calibration_without_io"] if p == "without inner orientation" else np.nan for p in test["processing"]]
    # the paper's a without inner orientation as a disparity error: constant bias of a/(δ_CCD/f) px
    test["paper_a_as_disparity_bias_px"] = PAPER["a_calibration_without_io"] / (1e3 * D2H_PIXEL_MM / D2H_NOMINAL_F_MM)
    write_table(test, out["test"])
    fig, ax = new_figure(figsize=(5.5, 3.8))
    Ls = np.linspace(0, test["L_m"].max() * 1.05, 50)
    for label, colour in (("with inner orientation", "tab:blue"), ("without inner orientation", "tab:red")):
        g = test[test.processing == label]
        ax.plot(g["L_m"], g["mae_z_mm"], "o", color=colour, label=f"{label}: a = {fits[label][0]:.4f} mm/m")
        ax.plot(Ls, fits[label][0] * Ls, "-", color=colour)
        ax.plot(Ls, g["a_paper_mm_per_m"].iloc[0] * Ls, ":", color=colour, label=f"paper a = {g['a_paper_mm_per_m'].iloc[0]} mm/m")
    for (label, mk) in zip([v[0] for v in variants[2:]], ("^", "v", "x")):
        g = test[test.processing == label]
        ax.plot(g["L_m"], g["mae_z_mm"], mk, color="0.4", ms=4, label=label)
    ax.set_yscale("symlog", linthresh=0.05)
    ax.set_xlabel("L = H²/B (m)")
    ax.set_ylabel("MAE of height at 22 check targets (mm)")
    ax.legend()
    save_figure(fig, out["test_png"], "kitegully stereo twin after Moritani et al. (2010)")
    log.info("calibration rule done in %.1f s", time.perf_counter() - t0)


# ----------------------------------------------------------------------------- rule: dry box
def measure_dry_box(cfg: Mapping[str, Any], cameras_json: str, seed: int, out: Mapping[str, str]) -> None:
    """Rule ``stereo_dry_box``: MAE vs L over the 11 set-ups and the 16 removals at L = 9.1 m.

    Parameters
    ----------
    cfg : mapping
        ``stereo.processing`` and ``stereo.dry_box``.
    cameras_json : str
        Calibrated cameras from :func:`calibrate_rig`.
    seed : int
    out : mapping
        ``mae_vs_L`` (csv), ``mae_vs_L_png``, ``removals`` (csv), ``removals_png``, ``dod_png``.

    Notes
    -----
    Cost: 11 + 17 rendered pairs of the box window (0.1–1 Mpx each) and their matching;
    about a minute on one core.
    """
    params = StereoParams.from_config(cfg)
    cams = _load_cameras(cameras_json)
    proc, db = params.processing, params.dry_box
    texture = soil_texture(rng_for(seed, "stereo", "texture"), TEXTURE_EXTENT)
    grid = _box_grid(proc["cell_mm"] * 1e-3)
    ref = _cell_truth(_relief, grid)
    extent = np.array([[x, y, z] for x in (BOX[0], BOX[2]) for y in (BOX[1], BOX[3]) for z in (-0.01, 0.01)])  # the soil, not the frame
    diameter = proc["mark_diameter_mm"] * 1e-3
    marks = PrintedMarks(_frame_marks(), MarkDesign(diameter))
    match = MatchParams(**proc["matching"])
    rows = []
    for H, B in (tuple(float(v) for v in s) for s in db["setups"]):
        rng = rng_for(seed, "stereo", "dry_box", f"{H}-{B}")
        truth = paper_rig(H, B)
        L_img, R_img = _render_pair(truth, _relief, texture, proc["image_noise_dn"], rng, extent, marks)
        pp = PairProcessor.from_images(cams, L_img, R_img, _survey(marks.xyz, rng, proc), diameter, B, H, match)
        dem, n, disp = pp.dem(L_img, R_img, grid, return_disparity=True)
        ok = dem.valid
        # evaluation: the achieved matching precision δ (px) and the DEM error split into plane + rest
        prec = matching_residual_px(pp.rect, disp, truth, _relief, grid)
        dec = error_decomposition(dem.data, ref, grid)
        # point measurement: 20 nail heads matched by hand, against the point gauge (±0.01 mm)
        nails = _nails(rng)
        heads = np.column_stack([nails, _relief(nails[:, 0], nails[:, 1]) + 0.02])
        gauge = heads[:, 2] + rng.normal(0, 1e-5, len(heads))
        ms = proc["manual_sigma_px"]
        P = pp.points(truth.left.project(heads, truth.pose_left) + rng.normal(0, ms, (20, 2)),
                      truth.right.project(heads, truth.pose_right) + rng.normal(0, ms, (20, 2)))
        dz_model = delta_z_m(H, B, cams["left"]) * 1e3
        rows.append({"H_m": H, "B_m": B, "L_m": float(stereo_L_m(H, B)), "matched_px": n,
                     "point_mae_mm": 1e3 * mae(gauge, P[:, 2]), "surface_mae_mm": 1e3 * mae(ref[ok], dem.data[ok]),
                     "surface_mean_error_mm": 1e3 * float(np.mean(dem.data[ok] - ref[ok])), "dem_cover_pct": 100 * float(ok.mean()),
                     "dz_1px_mm": dz_model, "sigma_d_px": prec["sigma_d_px"], "bias_d_px": prec["bias_d_px"],
                     "y_parallax_rms_px": prec["y_parallax_rms_px"], "surface_tilt_error_mm_per_m": dec["tilt_mm_per_m"],
                     "surface_plane_mae_mm": dec["plane_mae_mm"], "surface_residual_mae_mm": dec["residual_mae_mm"],
                     **_pair_columns(pp, truth, marks.xyz)})
        log.info("dry box H %.2f B %.2f: point MAE %.3f mm, surface MAE %.3f mm; %d tie points (Sampson RMS %.3f px), "
                 "marks %.4f px from the truth, similarity residual %.3f mm", H, B, rows[-1]["point_mae_mm"], rows[-1]["surface_mae_mm"],
                 pp.info["ties_inliers"], pp.info["tie_sampson_rms_px"], rows[-1]["mark_error_px"], pp.info["mark_abs_rms_mm"])
    tab = pd.DataFrame(rows)
    a_pt, r2_pt = fit_mae_vs_L(tab["L_m"], tab["point_mae_mm"])
    a_s, r2_s = fit_mae_vs_L(tab["L_m"], tab["surface_mae_mm"])
    # σ_d equivalent: the matching precision that would explain the surface MAE through the δz model alone
    # (the stage has no true disparity; the matcher's own σ_d is MATCHING_PRECISION_PX, measured by the benchmark)
    sd = float(np.sum(tab["surface_mae_mm"] * tab["dz_1px_mm"]) / np.sum(tab["dz_1px_mm"] ** 2)) / np.sqrt(2 / np.pi)
    tab["a_point_fit_mm_per_m"], tab["r2_point"], tab["a_surface_fit_mm_per_m"], tab["r2_surface"] = a_pt, r2_pt, a_s, r2_s
    tab["a_point_paper"], tab["a_surface_paper"] = PAPER["a_point"], PAPER["a_surface"]
    tab["dz_model_slope_per_px_mm_per_m"] = float(np.mean(tab["dz_1px_mm"] / tab["L_m"]))
    tab["sigma_d_equivalent_px"] = sd
    tab["dz_model_a_mm_per_m"] = float(np.sqrt(2 / np.pi) * np.mean(tab["dz_1px_mm"] / tab["L_m"]) * MATCHING_PRECISION_PX)
    # the δz model at the precision achieved in this run (δ measured per set-up against the twin's surface)
    delta = float(np.nanmedian(tab["sigma_d_px"]))
    k = float(np.mean(tab["dz_1px_mm"] / tab["L_m"]))
    tab["sigma_d_measured_median_px"] = delta
    tab["dz_model_a_measured_mm_per_m"] = float(np.sqrt(2 / np.pi) * k * delta)
    a_res, r2_res = fit_mae_vs_L(tab["L_m"], tab["surface_residual_mae_mm"])
    a_pl, r2_pl = fit_mae_vs_L(tab["L_m"], tab["surface_plane_mae_mm"])
    tab["a_surface_residual_mm_per_m"], tab["r2_surface_residual"] = a_res, r2_res
    tab["a_surface_plane_mm_per_m"], tab["r2_surface_plane"] = a_pl, r2_pl
    # [I] what the image measurement of the 10 frame marks alone predicts for the box-mean height:
    # each mark's height from a disparity measured to √2·σ_mark px (σ_mark: the marks' measured error), averaged over 10 marks
    tab["dz_model_a_marks_offset_mm_per_m"] = float(np.sqrt(2 / np.pi) * k * np.sqrt(2) * np.median(tab["mark_error_px"]) / np.sqrt(10))
    log.info("dry box: δ = %.3f px; surface a = %.4f (plane part %.4f, rest %.4f) vs δz model %.4f mm/m",
             delta, a_s, a_pl, a_res, float(np.sqrt(2 / np.pi) * k * delta))
    write_table(tab, out["mae_vs_L"])
    fig, ax = new_figure(figsize=(5.5, 3.8))
    Ls = np.linspace(0, tab["L_m"].max() * 1.05, 50)
    k = float(np.mean(tab["dz_1px_mm"] / tab["L_m"]))
    ax.plot(tab["L_m"], tab["point_mae_mm"], "s", color="tab:orange", label=f"point (20 nails): a = {a_pt:.4f} mm/m")
    ax.plot(Ls, a_pt * Ls, "-", color="tab:orange")
    ax.plot(tab["L_m"], tab["surface_mae_mm"], "o", color="tab:blue", label=f"surface (DEM): a = {a_s:.4f} mm/m")
    ax.plot(Ls, a_s * Ls, "-", color="tab:blue")
    ax.plot(tab["L_m"], tab["surface_residual_mae_mm"], "d", color="tab:green", ms=4,
            label=f"surface minus its error plane: a = {a_res:.4f} mm/m")
    ax.plot(Ls, np.sqrt(2 / np.pi) * k * delta * Ls, "--", color="k",
            label=f"δz model, MAE = √(2/π)·L·δ_CCD·δ/f, δ = {delta:.3f} px (measured)")
    ax.plot(Ls, PAPER["a_point"] * Ls, ":", color="tab:orange", label="paper point a = 0.049")
    ax.plot(Ls, PAPER["a_surface"] * Ls, ":", color="tab:blue", label="paper surface a = 0.030")
    ax.set_xlabel("L = H²/B (m)")
    ax.set_ylabel("MAE (mm)")
    ax.legend(fontsize=7)
    save_figure(fig, out["mae_vs_L_png"], "kitegully stereo twin after Moritani et al. (2010)")

    # 16 removals at L = 9.1 m
    H, B = float(db["removal_H_m"]), float(db["removal_B_m"])
    rng = rng_for(seed, "stereo", "removals")
    truth = paper_rig(H, B)
    surveyed = _survey(marks.xyz, rng, proc)
    S_cm2 = (BOX[2] - BOX[0]) * (BOX[3] - BOX[1]) * 1e4
    rho = float(db["bulk_density"])
    V_m3 = float(db["removal_ml"]) * 1e-6
    phases = rng.uniform(0, 2 * np.pi, (int(db["removals"]), 2))
    lx, ly = BOX[2] - BOX[0], BOX[3] - BOX[1]

    def surface(k):
        # removal j lowers the soil by (V/S)·(1 + ½·cos(2πx/lx + φj)·cos(2πy/ly + ψj)) [I]: uneven scraping
        # whose mean over the box is exactly V/S. The sum over j collapses to two complex phasors
        # (cos a·cos b = ½[cos(a+b) + cos(a−b)]), so a state costs 4 trig evaluations, not 2k.
        c1 = np.exp(1j * (phases[:k, 0] + phases[:k, 1])).sum()
        c2 = np.exp(1j * (phases[:k, 0] - phases[:k, 1])).sum()
        d = V_m3 / (S_cm2 * 1e-4)

        def h(x, y):
            u, v = 2 * np.pi * x / lx, 2 * np.pi * y / ly
            wsum = k + 0.25 * (np.real(np.exp(1j * (u + v)) * c1) + np.real(np.exp(1j * (u - v)) * c2))
            return _relief(x, y) - d * wsum
        return h

    # [I] scraping soil off exposes new soil: each state has its own texture, so the matching
    # errors of two epochs are independent (the same texture would cancel them in the DoD)
    imgs0 = _render_pair(truth, surface(0), texture, proc["image_noise_dn"], rng, extent, marks)
    pp = PairProcessor.from_images(cams, *imgs0, surveyed, diameter, B, H, match)
    d0, _ = pp.dem(*imgs0, grid)
    rrows, marks_uv = [], [np.hstack(pp.info["marks_uv"])]
    for k in range(1, int(db["removals"]) + 1):
        tex_k = soil_texture(rng_for(seed, "stereo", "texture_removal", k), TEXTURE_EXTENT)
        imgs = _render_pair(truth, surface(k), tex_k, proc["image_noise_dn"], rng, extent, marks)
        ppk = pp.reoriented_from_images(*imgs) if proc["reorient_each_pair"] else pp
        marks_uv.append(np.hstack(ppk.info["marks_uv"]))
        dk, _ = ppk.dem(*imgs, grid)
        ok = d0.valid & dk.valid
        mass_g = rho * k * V_m3 * 1e6 + rng.normal(0, 0.1)  # balance read to 0.1 g [I]
        M = 10 * mass_g / (rho * S_cm2)
        A = -1e3 * float(np.mean(dk.data[ok] - d0.data[ok]))
        rrows.append({"removal": k, "removed_ml": k * float(db["removal_ml"]), "mass_g": mass_g, "M_s_mm": M, "A_s_mm": A,
                      "abs_error_mm": abs(A - M), "rel_error_pct": 100 * abs(A - M) / M})
        if k == int(db["removals"]):
            _dod_figure(dk.data - d0.data, grid, f"Dry box, {k} removals (L = {stereo_L_m(H, B):.1f} m)", out["dod_png"])
    rem = pd.DataFrame(rrows)
    # repeatability of the mark measurement: the rig does not move between removals, so each mark's
    # position scatters over the 17 pairs by the measurement alone (std per coordinate, RMS over marks and images)
    rem["mark_repeatability_px"] = float(np.sqrt(np.mean(np.std(np.array(marks_uv), axis=0, ddof=1) ** 2)))
    for key, v in _pair_columns(pp, truth, marks.xyz).items():
        rem[f"first_pair_{key}"] = v
    b, r2 = fit_A_vs_M(rem["M_s_mm"], rem["A_s_mm"])
    rem["b_fit"], rem["r2_fit"] = b, r2
    rem["MAE_mm"], rem["MRE_pct"] = mae(rem["M_s_mm"], rem["A_s_mm"]), mre(rem["M_s_mm"], rem["A_s_mm"])
    rem["b_paper"], rem["MAE_paper_mm"], rem["MRE_paper_pct"] = PAPER["b"], PAPER["mae_9_1_mm"], PAPER["mre_9_1_pct"]
    write_table(rem, out["removals"])
    fig, ax = new_figure(figsize=(4.5, 4.0))
    ax.plot(rem["M_s_mm"], rem["A_s_mm"], "o", label=f"removals: b = {b:.3f} (R² {r2:.3f})")
    m = np.linspace(0, rem["M_s_mm"].max() * 1.05, 20)
    ax.plot(m, b * m, "-", label="fit A = b·M")
    ax.plot(m, PAPER["b"] * m, ":", label="paper b = 1.06")
    ax.set_xlabel("gravimetric depth M_s (mm)")
    ax.set_ylabel("DEM lowering A_s (mm)")
    ax.legend()
    save_figure(fig, out["removals_png"], "kitegully stereo twin after Moritani et al. (2010)")


# ----------------------------------------------------------------------------- rule: rain
def settlement_mm(rho_b: float, seal_depth_mm: float, seal_density: float) -> float:
    """Final settlement of loose soil compacted by rain: ``s = d·(1 − ρ_b/ρ_seal)`` (mm); 0 if ρ_b ≥ ρ_seal.

    Parameters
    ----------
    rho_b : float
        Bulk density of the loose soil (g/cm³).
    seal_depth_mm : float
        Depth the rain compacts (mm).
    seal_density : float
        Density the compacted layer reaches (g/cm³).

    Returns
    -------
    float
        Settlement s (mm).
    """
    return float(seal_depth_mm * max(0.0, 1.0 - rho_b / seal_density))


def interrill_rate_kg_m2_h(K_i: float, intensity_mm_h: float, slope_deg: float) -> float:
    """WEPP interrill detachment ``D_i = K_i·I²·S_f`` with ``S_f = 1.05 − 0.85·exp(−4·sin θ)`` (kg/m²/h).

    Parameters
    ----------
    K_i : float
        Interrill erodibility (kg·s/m⁴).
    intensity_mm_h : float
        Rain intensity I (mm/h).
    slope_deg : float
        Slope θ (degrees).

    Returns
    -------
    float
        Detachment rate D_i (kg/m²/h).
    """
    I = intensity_mm_h * 1e-3 / 3600.0
    Sf = 1.05 - 0.85 * np.exp(-4 * np.sin(np.radians(slope_deg)))
    return float(K_i * I * I * Sf * 3600.0)


def runoff_detachment_kg_m2_h(y_m: np.ndarray, intensity_mm_h: float, ksat_mm_h: float, slope_deg: float, manning_n: float,
                              K_r: float, tau_c: float) -> tuple[np.ndarray, np.ndarray]:
    """Flow shear and WEPP flow detachment of the sheet flow that accumulates down the box.

    Steady runoff per unit width ``q = (I − Ksat)·y`` (``y`` horizontal distance from the
    upslope wall), Manning depth ``h = (n q / √S)^(3/5)`` with ``S = sin θ``, shear
    ``τ = ρ g h S`` and detachment ``D_f = K_r·max(τ − τ_c, 0)`` (WEPP's rill equation without
    the transport-capacity feedback, an upper bound).

    Parameters
    ----------
    y_m : ndarray
        Distance from the upslope wall (m), ≥ 0.
    intensity_mm_h, ksat_mm_h : float
        Rain intensity and saturated conductivity (mm/h); no runoff where Ksat ≥ I.
    slope_deg : float
        Slope (deg).
    manning_n : float
        Manning roughness (s/m^(1/3)).
    K_r, tau_c : float
        Flow erodibility (s/m) and critical shear stress (Pa).

    Returns
    -------
    (ndarray, ndarray)
        Shear stress τ (Pa) and detachment D_f (kg/m²/h) at ``y_m``.
    """
    r = max(intensity_mm_h - ksat_mm_h, 0.0) * 1e-3 / 3600.0
    S = np.sin(np.radians(slope_deg))
    q = r * np.asarray(y_m, float)
    h = (manning_n * q / np.sqrt(max(S, 1e-12))) ** 0.6
    tau = 1000.0 * 9.81 * h * S
    return tau, K_r * np.maximum(tau - tau_c, 0.0) * 3600.0


def measure_rain(cfg: Mapping[str, Any], cameras_json: str, seed: int, out: Mapping[str, str]) -> None:
    """Rule ``stereo_rain``: the three bulk densities, a pair every ``interval_min``; MAE, MRE, upstream–downstream.

    Parameters
    ----------
    cfg : mapping
        ``stereo.processing`` and ``stereo.rain``.
    cameras_json : str
    seed : int
    out : mapping
        ``rain_runs`` (csv), ``rain_series`` (csv) and ``dod_png_<i>`` per density.
    """
    params = StereoParams.from_config(cfg)
    cams = _load_cameras(cameras_json)
    proc, rn = params.processing, params.rain
    texture = soil_texture(rng_for(seed, "stereo", "texture_rain"), TEXTURE_EXTENT)
    tan = np.tan(np.radians(rn["slope_deg"]))
    grid = _box_grid(proc["cell_mm"] * 1e-3)
    extent = np.array([[x, y, -tan * y + dz] for x in (BOX[0], BOX[2]) for y in (BOX[1], BOX[3]) for dz in (-0.01, 0.01)])
    S_cm2 = (BOX[2] - BOX[0]) * (BOX[3] - BOX[1]) * 1e4
    rate = interrill_rate_kg_m2_h(rn["interrill_erodibility"], rn["intensity_mm_h"], rn["slope_deg"])

    def erosion_rate(y):
        """Total detachment (kg/m²/h) at y: interrill + runoff-driven flow detachment (distance from the upslope wall)."""
        return rate + runoff_detachment_kg_m2_h(np.clip(np.asarray(y, float) - BOX[1], 0.0, None), rn["intensity_mm_h"], rn["ksat_mm_h"],
                                                rn["slope_deg"], rn["manning_n"], rn["rill_erodibility_s_m"], rn["critical_shear_pa"])[1]

    # the model's own upstream − downstream difference of erosion per hour (central 80 % of the box, halves along y)
    yy = np.linspace(BOX[1], BOX[3], 2001)
    ys = np.sqrt(0.8) * (BOX[3] - BOX[1]) / 2
    e_up = float(np.mean(erosion_rate(yy[(yy >= -ys) & (yy < 0)])))
    e_down = float(np.mean(erosion_rate(yy[(yy >= 0) & (yy <= ys)])))
    tau_max = float(runoff_detachment_kg_m2_h(np.array([BOX[3] - BOX[1]]), rn["intensity_mm_h"], rn["ksat_mm_h"], rn["slope_deg"],
                                              rn["manning_n"], rn["rill_erodibility_s_m"], rn["critical_shear_pa"])[0][0])
    box_rate = float(np.mean(erosion_rate(yy)))  # kg/m²/h over the whole box: what leaves it as sediment
    diameter = proc["mark_diameter_mm"] * 1e-3
    match = MatchParams(**proc["matching"])
    times = np.arange(0, rn["duration_min"] + 1e-9, rn["interval_min"])
    runs, series = [], []
    for i, rho in enumerate(_floats(rn["bulk_densities"], "stereo.rain.bulk_densities")):
        rng = rng_for(seed, "stereo", "rain", f"{rho}")
        s_max = settlement_mm(rho, rn["seal_depth_mm"], rn["seal_density"])
        truth = paper_rig(rn["H_m"], rn["B_m"])
        # the box slopes down towards +y (y = −0.25 m is upstream), 10°
        # the frame slopes with the box: its marks 1 cm above the sloping soil, on plates parallel to it
        marks = PrintedMarks(_frame_marks() + np.c_[np.zeros((10, 2)), -tan * _frame_marks()[:, 1]], MarkDesign(diameter), dz_dy=-tan)
        surveyed = _survey(marks.xyz, rng, proc)

        def surface(t_min, rho=rho, s_max=s_max):
            settle = s_max * (1 - np.exp(-t_min / rn["settle_min"])) * 1e-3
            # m of soil at ρ_b: uniform interrill detachment + flow detachment growing with the runoff from the upslope wall
            return lambda x, y: -tan * y + _relief(x, y) - settle - erosion_rate(y) * t_min / 60.0 / (rho * 1e3)

        imgs0 = _render_pair(truth, surface(0.0), texture, proc["image_noise_dn"], rng, extent, marks)
        pp = PairProcessor.from_images(cams, *imgs0, surveyed, diameter, rn["B_m"], rn["H_m"], match)
        d0, _ = pp.dem(*imgs0, grid)
        Ms, As, up_down = [], [], None
        for t in times[1:]:
            # [I] splash and wash rearrange the surface grains: a new texture per pair
            tex_t = soil_texture(rng_for(seed, "stereo", "texture_rain", f"{rho}", int(t)), TEXTURE_EXTENT)
            imgs = _render_pair(truth, surface(float(t)), tex_t, proc["image_noise_dn"], rng, extent, marks)
            ppt = pp.reoriented_from_images(*imgs) if proc["reorient_each_pair"] else pp
            dt_, _ = ppt.dem(*imgs, grid)
            ok = d0.valid & dt_.valid
            mass = box_rate * 1e3 / 1e4 * S_cm2 * t / 60.0 + rng.normal(0, 0.1)  # g of oven-dry sediment
            M = 10 * mass / (rho * S_cm2)
            lower = -(dt_.data - d0.data) * 1e3
            A = float(np.mean(lower[ok]))
            Ms.append(M)
            As.append(A)
            series.append({"bulk_density_g_cm3": rho, "t_min": float(t), "M_s_mm": M, "A_s_mm": A,
                           "settlement_true_mm": s_max * (1 - np.exp(-t / rn["settle_min"]))})
            if t == times[-1]:
                half = grid.height // 2  # rows: north (y large, downstream) first
                up = np.nanmean(np.where(ok, lower, np.nan)[half:])
                down = np.nanmean(np.where(ok, lower, np.nan)[:half])
                up_down = float(up - down)
                _dod_figure(dt_.data - d0.data, grid, f"Rain, ρ_b {rho} g/cm³, {t:.0f} min", out[f"dod_png_{i}"])
        runs.append({"bulk_density_g_cm3": rho, "settlement_param_mm": s_max, "erosion_rate_kg_m2_h": box_rate,
                     "interrill_rate_kg_m2_h": rate, "flow_shear_max_pa": tau_max, "critical_shear_pa": rn["critical_shear_pa"],
                     "upstream_minus_downstream_model_mm": (e_up - e_down) * rn["duration_min"] / 60.0 / (rho * 1e3) * 1e3,
                     "pairs": len(times), "M_s_final_mm": Ms[-1], "A_s_final_mm": As[-1],
                     "MAE_mm": mae(Ms, As), "MRE_pct": mre(Ms, As),
                     "MAE_paper_mm": PAPER["rain"].get(rho, (np.nan, np.nan))[0], "MRE_paper_pct": PAPER["rain"].get(rho, (np.nan, np.nan))[1],
                     "upstream_minus_downstream_mm": up_down, "upstream_minus_downstream_paper_mm": PAPER["upstream_minus_downstream_mm"],
                     **{f"first_pair_{k}": v for k, v in _pair_columns(pp, truth, marks.xyz).items()}})
        log.info("rain ρ_b %.2f: MAE %.3f mm, MRE %.1f %%", rho, runs[-1]["MAE_mm"], runs[-1]["MRE_pct"])
    write_table(pd.DataFrame(runs), out["rain_runs"])
    write_table(pd.DataFrame(series), out["rain_series"])


# ----------------------------------------------------------------------------- rule: wind
def measure_wind(cfg: Mapping[str, Any], cameras_json: str, seed: int, out: Mapping[str, str]) -> None:
    """Rule ``stereo_wind``: the sand tray before and after 45 min of wind; MAE at the 20 nails and mean lowering.

    Parameters
    ----------
    cfg : mapping
        ``stereo.processing`` and ``stereo.wind``.
    cameras_json : str
    seed : int
    out : mapping
        ``wind_run`` (csv), ``dod_png``.
    """
    params = StereoParams.from_config(cfg)
    cams = _load_cameras(cameras_json)
    proc, wd = params.processing, params.wind
    H, B = float(wd["H_m"]), float(wd["B_m"])
    # the part of the 2.0 × 0.45 m tray both cameras see at H = 0.6 m: a 0.12 × 0.12 m patch of sand
    box = (-0.06, -0.06, 0.06, 0.06)
    # [I] sand texture at ~0.7 ground pixel (0.08 mm at H = 0.6 m), grains 2-50 cells
    cell = float(np.clip(H * D2H_PIXEL_MM / 51.4 / 1.4, 8e-5, 2.5e-4))
    sand = dict(cell_m=cell, scales_m=(2 * cell, 5 * cell, 15 * cell, 50 * cell))
    texture = soil_texture(rng_for(seed, "stereo", "texture_sand"), (-0.12, -0.12, 0.12, 0.12), **sand)
    lam, amp = wd["ripple_wavelength_mm"] * 1e-3, wd["ripple_mm"] * 1e-3
    defl = wd["deflation_mm"] * 1e-3

    def surface(after: bool):
        shift = 0.5 * lam if after else 0.0
        return lambda x, y: 0.5 * amp * np.sin(2 * np.pi * (x - shift) / lam + 0.3 * np.sin(2 * np.pi * y / 0.05)) - (defl if after else 0.0)

    rng = rng_for(seed, "stereo", "wind")
    truth = paper_rig(H, B)
    diameter = wd["mark_diameter_mm"] * 1e-3
    marks = PrintedMarks(_frame_marks(box), MarkDesign(diameter))
    grid = _box_grid(wd["cell_mm"] * 1e-3, box)
    extent = np.array([[x, y, z] for x in (box[0], box[2]) for y in (box[1], box[3]) for z in (-0.003, 0.003)])
    imgs0 = _render_pair(truth, surface(False), texture, proc["image_noise_dn"], rng, extent, marks)
    pp = PairProcessor.from_images(cams, *imgs0, _survey(marks.xyz, rng, proc), diameter, B, H, MatchParams(**proc["matching"]))
    d0, _ = pp.dem(*imgs0, grid)
    texture1 = soil_texture(rng_for(seed, "stereo", "texture_sand_after"), (-0.12, -0.12, 0.12, 0.12), **sand)  # [I] new grains
    d1, _ = pp.dem(*_render_pair(truth, surface(True), texture1, proc["image_noise_dn"], rng, extent, marks), grid)
    nails = _nails(rng, box)
    gauge_before = _cell_truth(surface(False), grid)
    gauge_after = _cell_truth(surface(True), grid)
    r, c = grid.index(nails[:, 0], nails[:, 1])
    ok = d0.valid[r, c] & d1.valid[r, c]
    M_i = (gauge_before - gauge_after)[r, c][ok] * 1e3 + rng.normal(0, 0.01, ok.sum())  # micrometer ±0.01 mm
    A_i = (d0.data - d1.data)[r, c][ok] * 1e3
    both = d0.valid & d1.valid
    S_cm2 = (box[2] - box[0]) * (box[3] - box[1]) * 1e4
    M_s = 10 * (wd["sand_density"] * defl * 1e2 * S_cm2) / (wd["sand_density"] * S_cm2)
    A_s = float(np.mean((d0.data - d1.data)[both])) * 1e3
    row = {"H_m": H, "B_m": B, "L_m": float(stereo_L_m(H, B)), "nails": int(ok.sum()), "MAE_nails_mm": mae(M_i, A_i),
           "M_s_mm": M_s, "A_s_mm": A_s, "surface_abs_error_mm": abs(A_s - M_s),
           "dod_mae_vs_gauge_mm": 1e3 * mae((gauge_before - gauge_after)[both], (d0.data - d1.data)[both]),
           "MAE_paper_mm": PAPER["wind_mae_mm"], **_pair_columns(pp, truth, marks.xyz)}
    write_table(pd.DataFrame([row]), out["wind_run"])
    _dod_figure(d1.data - d0.data, grid, "Wind tunnel, 45 min at 4.5 m/s", out["dod_png"])
    log.info("wind: MAE at nails %.3f mm", row["MAE_nails_mm"])
