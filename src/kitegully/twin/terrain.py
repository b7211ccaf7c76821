"""Bare-earth terrain of the twin: a meandering valley draining to a small reservoir.

The valley is described in a frame ``(u, v)`` aligned with the flow: ``u`` grows
downstream along ``flow_azimuth_deg`` and ``v`` grows towards the right bank. The
valley axis meanders, ``v_axis(u) = offset + A·sin(2πu/λ)``, and ``vp = v − v_axis(u)``
is the distance across the valley from the axis. The surface is

``z = floor(u) + bank(vp) + dam(u, vp) + fractal micro-relief``

with a right bank that is smooth and long (marl dip slope, where most gullies form) and a
left bank with sandstone ledges (Feurer et al. 2018, sect. 2.1). Every function is
vectorised and stateless, so any tile can be evaluated on its own.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from kitegully.twin.noise import fbm_grid, octaves

if TYPE_CHECKING:
    from kitegully.twin.site import TwinParams


@dataclass(frozen=True)
class Valley:
    """Geometry of the valley, the dam and the reservoir (all lengths in m)."""

    cx: float
    cy: float
    azimuth_rad: float
    axis_offset: float
    meander_amplitude: float
    meander_wavelength: float
    outlet_elevation: float
    long_slope: float
    floor_half_width: float
    floor_cross_slope: float
    right_relief: float
    right_width: float
    left_relief: float
    left_width: float
    ledges: int
    ledge_strength: float
    plateau_slope: float
    u_min: float
    u_max: float
    u_dam: float
    dam_crest_width: float
    dam_side_slope: float
    dam_half_length: float
    water_level: float
    dam_crest: float
    lake_u_min: float

    # --- frame -------------------------------------------------------------------------
    @property
    def flow(self) -> tuple[float, float]:
        """Unit vector (east, north) down the valley, at azimuth ``azimuth_rad``."""
        return float(np.sin(self.azimuth_rad)), float(np.cos(self.azimuth_rad))

    @property
    def right(self) -> tuple[float, float]:
        """Unit vector (east, north) towards the right bank: :attr:`flow` turned 90° clockwise."""
        return float(np.cos(self.azimuth_rad)), float(-np.sin(self.azimuth_rad))

    def uv(self, x: float | np.ndarray, y: float | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Map coordinates to (u downstream, v towards the right bank)."""
        (fx, fy), (rx, ry) = self.flow, self.right
        dx = np.asarray(x, dtype=np.float64) - self.cx
        dy = np.asarray(y, dtype=np.float64) - self.cy
        return dx * fx + dy * fy, dx * rx + dy * ry

    def xy(self, u: float | np.ndarray, v: float | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Frame coordinates back to map coordinates."""
        (fx, fy), (rx, ry) = self.flow, self.right
        u = np.asarray(u, dtype=np.float64)
        v = np.asarray(v, dtype=np.float64)
        return self.cx + u * fx + v * rx, self.cy + u * fy + v * ry

    def axis_v(self, u: float | np.ndarray) -> np.ndarray:
        """Across-valley position of the meandering axis at ``u``."""
        return self.axis_offset + self.meander_amplitude * np.sin(2.0 * np.pi * np.asarray(u) / self.meander_wavelength)

    def u_vp(self, x: float | np.ndarray, y: float | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(u, vp): along-valley position and signed distance from the axis (right > 0)."""
        u, v = self.uv(x, y)
        return u, v - self.axis_v(u)

    # --- elevation ---------------------------------------------------------------------
    def floor(self, u: float | np.ndarray) -> np.ndarray:
        """Valley-floor elevation: rises upstream of the dam with ``long_slope``."""
        return self.outlet_elevation + self.long_slope * (self.u_dam - np.asarray(u))

    def base(self, x: float | np.ndarray, y: float | np.ndarray) -> np.ndarray:
        """Smooth valley surface with the dam (no micro-relief, no gullies); O(n)."""
        u, vp = self.u_vp(x, y)
        z = self.floor(u) + self.bank(vp)
        return np.maximum(z, self.dam(u, vp))

    def bank(self, vp: float | np.ndarray) -> np.ndarray:
        """Cross-valley profile added to the floor elevation."""
        vp = np.asarray(vp, dtype=np.float64)
        a = np.abs(vp)
        z = self.floor_cross_slope * np.minimum(a, self.floor_half_width)
        right = np.clip((vp - self.floor_half_width) / self.right_width, 0.0, None)
        left = np.clip((-vp - self.floor_half_width) / self.left_width, 0.0, None)
        n = max(self.ledges, 1)
        left_l = left + self.ledge_strength * np.sin(2.0 * np.pi * n * left) / (2.0 * np.pi * n)
        left_l = np.where(left < 1.0, left_l, left)
        z = z + self.right_relief * _smooth_ramp(right) + self.plateau_slope * self.right_width * np.clip(right - 1.0, 0, None)
        z = z + self.left_relief * _smooth_ramp(left_l) + self.plateau_slope * self.left_width * np.clip(left - 1.0, 0, None)
        return z

    def dam(self, u: float | np.ndarray, vp: float | np.ndarray) -> np.ndarray:
        """Elevation of the dam embankment (−inf away from it)."""
        du = np.abs(np.asarray(u) - self.u_dam) - 0.5 * self.dam_crest_width
        crest = self.dam_crest - self.dam_side_slope * np.clip(du, 0.0, None)
        return np.where(np.abs(vp) <= self.dam_half_length, crest, -np.inf)

    def lake_zone(self, u: float | np.ndarray) -> np.ndarray:
        """Where water can stand: between the tail of the reservoir and the dam."""
        u = np.asarray(u)
        return (u >= self.lake_u_min) & (u <= self.u_dam)


def _smooth_ramp(s):
    """Smoothstep on [0, 1], 1 beyond: S-shaped hillslope (concave foot, convex crest)."""
    s = np.clip(s, 0.0, 1.0)
    return s * s * (3.0 - 2.0 * s)


def valley_from_config(tw: TwinParams, bounds: tuple[float, float, float, float]) -> Valley:
    """Build the :class:`Valley` for a site extent from the twin's ``terrain`` and ``reservoir``."""
    t = tw.terrain
    r = tw.reservoir
    xmin, ymin, xmax, ymax = bounds
    cx, cy = 0.5 * (xmin + xmax), 0.5 * (ymin + ymax)
    az = np.deg2rad(t["flow_azimuth_deg"])
    fx, fy = np.sin(az), np.cos(az)
    us = [(x - cx) * fx + (y - cy) * fy for x in (xmin, xmax) for y in (ymin, ymax)]
    u_min, u_max = float(min(us)), float(max(us))
    u_dam = u_max - r["dam_distance_m"]
    water = t["outlet_elevation_m"] + r["lake_depth_m"]
    # [I] backwater reaches where the floor rises above the water level; 1.5x margin for the bank toe
    lake_len = 1.5 * r["lake_depth_m"] / max(t["long_slope"], 1e-6)
    return Valley(
        cx=cx, cy=cy, azimuth_rad=float(az),
        axis_offset=t["axis_offset_m"],
        meander_amplitude=t["meander_amplitude_m"],
        meander_wavelength=t["meander_wavelength_m"],
        outlet_elevation=t["outlet_elevation_m"],
        long_slope=t["long_slope"],
        floor_half_width=t["floor_half_width_m"],
        floor_cross_slope=t["floor_cross_slope"],
        right_relief=t["right_bank"]["relief_m"],
        right_width=t["right_bank"]["width_m"],
        left_relief=t["left_bank"]["relief_m"],
        left_width=t["left_bank"]["width_m"],
        ledges=int(t["left_bank"]["ledges"]),
        ledge_strength=t["left_bank"]["ledge_strength"],
        plateau_slope=t["plateau_slope"],
        u_min=u_min, u_max=u_max, u_dam=u_dam,
        dam_crest_width=r["crest_width_m"],
        dam_side_slope=r["side_slope"],
        dam_half_length=r["half_length_m"],
        water_level=water,
        dam_crest=water + r["freeboard_m"],
        lake_u_min=u_dam - lake_len,
    )


def relief_octaves(tw: TwinParams, min_wavelength: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Octaves of the fractal micro-relief; ``min_wavelength`` keeps only the coarse prefix.

    The prefix keeps the octave indices (and hence the noise seeds) of the full set, so a
    coarse surface is exactly the full surface without its finest octaves.
    """
    m = tw.terrain["microrelief"]
    wl, amp = octaves(m["amplitude_m"], m["max_wavelength_m"], m["min_wavelength_m"], m["hurst"])
    if min_wavelength is not None:
        keep = wl >= min_wavelength
        wl, amp = wl[keep], amp[keep]
    return wl, amp


def pregully_grid(valley: Valley, xs: np.ndarray, ys: np.ndarray, seed: int, wl: np.ndarray, amp: np.ndarray) -> np.ndarray:
    """Valley surface plus micro-relief on the grid ``ys × xs`` (float64), before gullies.

    Complexity O(n·octaves) for n cells.

    Parameters
    ----------
    valley : Valley
        The valley.
    xs, ys : ndarray
        Column and row coordinates of the grid (m).
    seed : int
        Seed of the micro-relief noise.
    wl, amp : ndarray
        Octave wavelengths (m) and amplitudes (m), as from :func:`relief_octaves`.

    Returns
    -------
    ndarray (len(ys), len(xs)) float64
        Elevation (m).
    """
    z = valley.base(xs[None, :], ys[:, None])
    return z + fbm_grid(xs - valley.cx, ys - valley.cy, seed, wl, amp)
