"""Flight planning for kite photogrammetry (Feurer et al. 2018 sect. 2.3; Moritani et al. 2010 eq. 1).

Given a camera, the flying heights wanted (or a target GSD), the worst-case flight angle,
the trigger interval and the operator's walking speed, compute for each strip: line length,
ground sampling distance, image footprint, forward overlap, stereo base-to-height ratio and
the expected vertical precision ``δz = (H/f)·(H/B)·p`` with p the pixel pitch.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pandas as pd


@dataclass(frozen=True)
class PlanningCamera:
    """A frame camera as the flight planner sees it: sensor size (mm), pixel count and lens.

    Not the imaging model of the twin's renderer (:class:`kitegully.twin.camera.Camera`,
    intrinsics in pixels with distortion); both read the same physical camera keys.

    Attributes
    ----------
    sensor_width_mm, sensor_height_mm : float
        Sensor size (long side, short side).
    image_width_px, image_height_px : int
        Image size in pixels (long side, short side).
    focal_length_mm : float
    long_side_across_track : bool
        True when the sensor's long side is across the walking direction.
    """

    sensor_width_mm: float
    sensor_height_mm: float
    image_width_px: int
    image_height_px: int
    focal_length_mm: float
    long_side_across_track: bool = True

    @property
    def pixel_pitch_m(self) -> float:
        """Pixel pitch (m), from the sensor width and the pixel count."""
        return self.sensor_width_mm / self.image_width_px * 1e-3

    def gsd_m(self, height_m: float | np.ndarray) -> float | np.ndarray:
        """Ground sampling distance ``H·p/f`` (m) for a nadir image at ``height_m``."""
        return np.asarray(height_m) * self.pixel_pitch_m / (self.focal_length_mm * 1e-3)

    def height_for_gsd(self, gsd_m: float) -> float:
        """Flying height (m) that gives ``gsd_m``."""
        return gsd_m * self.focal_length_mm * 1e-3 / self.pixel_pitch_m

    def footprint_m(self, height_m: float) -> tuple[float, float]:
        """Ground footprint (across track, along track) in metres: ``H·S/f``."""
        long_side = height_m * self.sensor_width_mm / self.focal_length_mm
        short_side = height_m * self.sensor_height_mm / self.focal_length_mm
        return (long_side, short_side) if self.long_side_across_track else (short_side, long_side)


def line_length_for_angle(height_m: float, flight_angle_deg: float) -> float:
    """Line length ``L = H / sin(α)`` that reaches ``height_m`` at a straight-line angle (m)."""
    return height_m / math.sin(math.radians(flight_angle_deg))


def stereo_precision_m(height_m: float, base_m: float, camera: PlanningCamera) -> float:
    """Vertical precision of a stereo pair ``δz = (H/f)·(H/B)·p`` (Moritani et al. 2010 eq. 1), m.

    Parameters
    ----------
    height_m : float
        Camera height above the ground (m).
    base_m : float
        Stereo base (m).
    camera : PlanningCamera
        Gives the focal length and the pixel pitch.

    Returns
    -------
    float
        δz (m); infinite when ``base_m`` ≤ 0.
    """
    if base_m <= 0:
        return float("inf")
    return (height_m / (camera.focal_length_mm * 1e-3)) * (height_m / base_m) * camera.pixel_pitch_m


def plan_flight(
    camera: PlanningCamera,
    flying_heights_m: list[float],
    worst_flight_angle_deg: float,
    trigger_interval_s: float,
    walking_speed_m_s: float,
    stereo_min_overlap: float,
    max_flying_height_m: float | None = None,
    target_gsd_m: float | None = None,
) -> pd.DataFrame:
    """Plan the strips of a kite survey.

    Parameters
    ----------
    camera
        The camera.
    flying_heights_m
        Heights of the strips (m), e.g. 120, 300, 500 for Kamech.
    worst_flight_angle_deg
        Lowest expected flight angle (50° in the paper); sets the line length ``H/sin(α)``.
    trigger_interval_s, walking_speed_m_s
        Intervalometer period (s) and operator speed (m/s); the kite moves with the
        operator, so the base between consecutive images is ``v·Δt``.
    stereo_min_overlap
        [I] Overlap two images must still share to form a stereo pair. The stereo base is
        the longest multiple of ``v·Δt`` that keeps this overlap; it sets B/H and δz.
    max_flying_height_m, target_gsd_m
        Optional caps: strips above the cap are dropped; a target GSD caps the height at
        ``GSD·f/p``.

    Returns
    -------
    pandas.DataFrame
        One row per strip with columns ``line_length_m, flying_height_m, gsd_m,
        footprint_across_m, footprint_along_m, forward_overlap, base_height_ratio,
        precision_z_m`` and, for information, ``downwind_offset_m, trigger_base_m,
        stereo_base_m, images_per_km``.
    """
    if not 0 < worst_flight_angle_deg < 90:
        raise ValueError("worst-case flight angle must be between 0 and 90 degrees")
    if trigger_interval_s <= 0 or walking_speed_m_s <= 0:
        raise ValueError("trigger interval and walking speed must be positive")
    if not 0 <= stereo_min_overlap < 1:
        raise ValueError("stereo_min_overlap must be in [0, 1)")
    cap = math.inf
    if max_flying_height_m is not None:
        cap = min(cap, max_flying_height_m)
    if target_gsd_m is not None:
        cap = min(cap, camera.height_for_gsd(target_gsd_m))
    heights = sorted(h for h in flying_heights_m if h <= cap + 1e-9)
    if not heights:
        raise ValueError(f"no flying height at or below the cap of {cap:.1f} m")
    rows = []
    trigger_base = walking_speed_m_s * trigger_interval_s
    for h in heights:
        length = line_length_for_angle(h, worst_flight_angle_deg)
        across, along = camera.footprint_m(h)
        overlap = 1.0 - trigger_base / along
        n_steps = math.floor(along * (1.0 - stereo_min_overlap) / trigger_base)
        stereo_base = max(n_steps, 1) * trigger_base
        rows.append(
            dict(
                line_length_m=length,
                flying_height_m=h,
                gsd_m=float(camera.gsd_m(h)),
                footprint_across_m=across,
                footprint_along_m=along,
                forward_overlap=overlap,
                base_height_ratio=stereo_base / h,
                precision_z_m=stereo_precision_m(h, stereo_base, camera),
                downwind_offset_m=math.sqrt(max(length**2 - h**2, 0.0)),
                trigger_base_m=trigger_base,
                stereo_base_m=stereo_base,
                images_per_km=1000.0 / trigger_base,
            )
        )
    return pd.DataFrame(rows)
