"""Simulated kite flight over a twin site: operator walk, camera track, triggers, GPS logs.

The operator walks parallel lines (azimuth ``line_azimuth_deg``) paying out the planned
line lengths; the camera sits downwind of the operator at the distance and height the
tether model gives for that line length and wind (Feurer et al. 2018, sect. 2.3:
``p_cam = p_op + L·cosα·ŵ + (0, 0, L·sinα)``). On top of that the simulation adds the
rig's pendulum tilt, the yaw drift of a rig that acts as a vane, gusty kite jitter and an
intervalometer. The strips are placed so the camera footprints cover the site with the
configured side overlap; from the intervalometer's shots every k-th is kept so the
forward overlap is near its target (as a photographer culls redundant frames).

All randomness comes from one ``numpy.random.Generator``. Cost: O(flight time / dt).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import datetime, timedelta, timezone
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence
from xml.sax.saxutils import escape

import numpy as np
import pandas as pd

from kitegully import InputError
from kitegully.config import config_section
from kitegully.twin.camera import Camera, Pose, nadir_rotation, rotation_to_quaternion

#: ``flight:`` keys :meth:`FlightSettings.from_config` accepts besides its own (read by other
#: parts of the flight stage; ``time_step_s`` has a default).
FLIGHT_OTHER_KEYS = ("time_step_s", "material", "kite", "line_lengths_m", "camera", "render", "gcps", "coverage",
                     "figures", "threads", "epochs")

#: Kite position relative to the operator's hand for a line length: (downwind_m, height_m).
KiteOffset = Callable[[float], tuple[float, float]]
#: Ground elevation (m) at map coordinates (vectorised).
GroundZ = Callable[[np.ndarray, np.ndarray], np.ndarray]


@dataclass(frozen=True)
class FlightSettings:
    """Parameters of the simulated flight (the ``flight`` config section, see its schema)."""

    wind_speed_m_s: float
    wind_from_deg: float
    line_azimuth_deg: float
    line_lengths_m: tuple[float, ...]
    walk_speed_m_s: float
    trigger_interval_s: float
    forward_overlap: float
    side_overlap: float
    along_extension: float
    min_site_fraction: float
    operator_hand_height_m: float
    rig_below_kite_m: float
    pendulum_length_m: float
    tilt_amplitude_deg: float
    yaw_offset_deg: float
    yaw_sd_deg: float
    yaw_correlation_s: float
    jitter_horizontal_m: float
    jitter_vertical_m: float
    jitter_correlation_s: float
    gps_sigma_m: float
    gps_vertical_sigma_m: float
    gps_correlation_s: float
    gps_interval_s: float
    start_time: datetime
    time_step_s: float = 0.05
    gravity_m_s2: float = 9.81

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any], line_lengths_m: Sequence[float]) -> "FlightSettings":
        """Settings from the ``flight:`` section (or the keys a rule passes of it).

        Raises
        ------
        InputError
            Naming a missing or unknown key (:func:`kitegully.config.config_section`), or a
            ``start_time`` that is not an ISO date-time.
        """
        names = [n for n in cls.__dataclass_fields__ if n not in ("line_lengths_m", "start_time", "gravity_m_s2")]
        required = [n for n in names if n != "time_step_s"] + ["start_time"]
        config_section(cfg, "flight", required, optional=FLIGHT_OTHER_KEYS)
        kw = {n: float(cfg[n]) for n in names if n in cfg}
        try:
            start = datetime.fromisoformat(str(cfg["start_time"]))
        except ValueError:
            raise InputError(f"flight.start_time: '{cfg['start_time']}' is not an ISO date-time") from None
        if start.tzinfo is not None:  # keep naive UTC (EXIF has no zone; GPX gets 'Z')
            start = start.astimezone(timezone.utc).replace(tzinfo=None)
        return cls(line_lengths_m=tuple(float(v) for v in line_lengths_m), start_time=start, **kw)

    @property
    def downwind_unit(self) -> np.ndarray:
        """Unit vector pointing downwind (east, north)."""
        az = np.radians(self.wind_from_deg + 180.0)
        return np.array([np.sin(az), np.cos(az)])

    @property
    def along_unit(self) -> np.ndarray:
        """Unit vector along the walked lines, towards ``line_azimuth_deg`` (east, north)."""
        az = np.radians(self.line_azimuth_deg)
        return np.array([np.sin(az), np.cos(az)])

    @property
    def across_unit(self) -> np.ndarray:
        """Unit vector across the walked lines, 90° clockwise of :attr:`along_unit` (east, north)."""
        az = np.radians(self.line_azimuth_deg + 90.0)
        return np.array([np.sin(az), np.cos(az)])

    @property
    def base_heading_deg(self) -> float:
        """Azimuth of the image top: downwind (the rig weathervanes) plus the mounting offset."""
        return (self.wind_from_deg + 180.0 + self.yaw_offset_deg) % 360.0


@dataclass
class Strip:
    """One walked line: operator start/end (x, y), line length and nominal camera height."""

    index: int
    start: np.ndarray
    end: np.ndarray
    line_length_m: float
    downwind_m: float
    height_m: float
    footprint_along_m: float
    footprint_across_m: float
    keep_every: int


@dataclass
class FlightResult:
    """Everything the flight produced (truth and observed)."""

    strips: list[Strip]
    poses: pd.DataFrame
    operator_track: pd.DataFrame
    camera_track: pd.DataFrame
    operator_gps: pd.DataFrame
    camera_gps: pd.DataFrame
    n_triggers: int
    summary: dict[str, Any] = field(default_factory=dict)


def ou_process(rng: np.random.Generator, n: int, dt: float, sigma: float, tau: float) -> np.ndarray:
    """Stationary Ornstein–Uhlenbeck series (sd ``sigma``, correlation time ``tau``).

    Parameters
    ----------
    rng : numpy.random.Generator
        Random stream.
    n : int
        Number of samples.
    dt : float
        Time step between samples (s).
    sigma : float
        Standard deviation of the series (its own unit); zeros when ≤ 0.
    tau : float
        Correlation time (s).

    Returns
    -------
    ndarray (n,) float64
        The series; the first sample is drawn from the stationary distribution.
    """
    if sigma <= 0 or n == 0:
        return np.zeros(n)
    a = np.exp(-dt / max(tau, 1e-9))
    eps = rng.standard_normal(n) * sigma * np.sqrt(1 - a * a)
    eps[0] = rng.standard_normal() * sigma
    # x_k = a x_{k-1} + eps_k as a linear filter (vectorised)
    from scipy.signal import lfilter

    return lfilter([1.0], [1.0, -a], eps)


def footprint_along_across(camera: Camera, height_m: float, settings: FlightSettings) -> tuple[float, float]:
    """Footprint extents (m) along and across the walking lines for a nadir view at ``height_m``.

    Parameters
    ----------
    camera : Camera
        The camera.
    height_m : float
        Camera height above the ground (m).
    settings : FlightSettings
        Gives the line azimuth and the image heading (:attr:`FlightSettings.base_heading_deg`).

    Returns
    -------
    along, across : float
        Extent of the footprint along and across the walking lines (m).
    """
    fw, fh = camera.footprint(height_m)
    k = np.radians(settings.base_heading_deg)
    up = np.array([np.sin(k), np.cos(k)])
    right = np.array([np.cos(k), -np.sin(k)])
    a, c = settings.along_unit, settings.across_unit
    along = abs(right @ a) * fw + abs(up @ a) * fh
    across = abs(right @ c) * fw + abs(up @ c) * fh
    return float(along), float(across)


def plan_strips(
    extent: tuple[float, float, float, float],
    camera: Camera,
    settings: FlightSettings,
    kite_offset: KiteOffset,
) -> list[Strip]:
    """Place the camera strips over the site and derive the operator's walking lines.

    Camera strips run along ``line_azimuth_deg``, spaced ``(1 − side_overlap)`` times the
    smallest across-track footprint, centred on the site and as many as needed to cover it;
    each extends ``along_extension`` footprints beyond the site at both ends. The line
    lengths cycle over the strips. The operator walks each camera strip shifted upwind by
    the kite's downwind distance.

    Parameters
    ----------
    extent : tuple of float
        Site extent ``(xmin, ymin, xmax, ymax)`` (m).
    camera : Camera
        The camera.
    settings : FlightSettings
        The flight settings.
    kite_offset : KiteOffset
        Kite position ``(downwind_m, height_m)`` relative to the operator's hand for a line length (m).

    Returns
    -------
    list of Strip
        The strips in walking order; odd strips run the other way.
    """
    xmin, ymin, xmax, ymax = extent
    centre = np.array([(xmin + xmax) / 2, (ymin + ymax) / 2])
    corners = np.array([[xmin, ymin], [xmin, ymax], [xmax, ymin], [xmax, ymax]]) - centre
    a_u, c_u = settings.along_unit, settings.across_unit
    a_span = corners @ a_u
    c_span = corners @ c_u
    offsets = {}
    for L in sorted(set(settings.line_lengths_m)):
        down, h = kite_offset(L)
        height = settings.operator_hand_height_m + h - settings.rig_below_kite_m
        if not np.isfinite(down) or height <= 1.0:
            raise InputError(f"flight.line_lengths_m: the kite does not fly usefully with {L:g} m of line at "
                             f"{settings.wind_speed_m_s:g} m/s (camera height {height:.1f} m)")
        offsets[L] = (down, height)
    h_min = min(h for _, h in offsets.values())
    _, across_min = footprint_along_across(camera, h_min, settings)
    spacing = (1.0 - settings.side_overlap) * across_min
    width = c_span.max() - c_span.min()
    n = max(1, int(np.ceil(max(width - across_min, 0.0) / spacing - 1e-9)) + 1)
    strips = []
    step = settings.walk_speed_m_s * settings.trigger_interval_s
    for i in range(n):
        L = settings.line_lengths_m[i % len(settings.line_lengths_m)]
        down, height = offsets[L]
        f_al, f_ac = footprint_along_across(camera, height, settings)
        ext = settings.along_extension * f_al
        c = (c_span.min() + c_span.max()) / 2 + (i - (n - 1) / 2) * spacing
        a0, a1 = a_span.min() - ext, a_span.max() + ext
        if i % 2:
            a0, a1 = a1, a0
        cam0 = centre + a0 * a_u + c * c_u
        cam1 = centre + a1 * a_u + c * c_u
        shift = down * settings.downwind_unit
        keep = max(1, int(round((1.0 - settings.forward_overlap) * f_al / step)))
        strips.append(Strip(i, cam0 - shift, cam1 - shift, L, down, height, f_al, f_ac, keep))
    return strips


def footprint_site_fraction(
    camera: Camera, xy: np.ndarray, height_m: float, heading_deg: float, extent: tuple[float, float, float, float]
) -> float:
    """Share of a nadir footprint (planned height, given heading) that lies inside the extent.

    Parameters
    ----------
    camera : Camera
        The camera.
    xy : ndarray (2,)
        Centre of the footprint (m).
    height_m : float
        Planned camera height above the ground (m).
    heading_deg : float
        Azimuth of the image top (degrees).
    extent : tuple of float
        Site extent ``(xmin, ymin, xmax, ymax)`` (m).

    Returns
    -------
    float
        Share (0 to 1) of a 12 × 12 grid of points over the footprint that lie inside the extent.
    """
    fw, fh = camera.footprint(height_m)
    k = np.radians(heading_deg)
    up = np.array([np.sin(k), np.cos(k)])
    right = np.array([np.cos(k), -np.sin(k)])
    g = (np.arange(12) + 0.5) / 12 - 0.5
    a, b = np.meshgrid(g * fw, g * fh)
    pts = xy + a.ravel()[:, None] * right + b.ravel()[:, None] * up
    xmin, ymin, xmax, ymax = extent
    inside = (pts[:, 0] >= xmin) & (pts[:, 0] <= xmax) & (pts[:, 1] >= ymin) & (pts[:, 1] <= ymax)
    return float(inside.mean())


def _walk(strips: list[Strip], speed: float, dt: float):
    """Operator positions along strips and transits at constant speed, with per-sample info."""
    pts, lengths, strip_id = [], [], []
    for k, s in enumerate(strips):
        if k > 0:
            prev = strips[k - 1]
            pts.append((prev.end, s.start))
            lengths.append((prev.line_length_m, s.line_length_m))
            strip_id.append(-1)
        pts.append((s.start, s.end))
        lengths.append((s.line_length_m, s.line_length_m))
        strip_id.append(s.index)
    seg_len = np.array([np.linalg.norm(b - a) for a, b in pts])
    seg_t = seg_len / speed
    t_end = np.concatenate([[0.0], np.cumsum(seg_t)])
    t = np.arange(0.0, t_end[-1] + 1e-9, dt)
    seg = np.clip(np.searchsorted(t_end, t, side="right") - 1, 0, len(pts) - 1)
    frac = np.where(seg_t[seg] > 0, (t - t_end[seg]) / np.maximum(seg_t[seg], 1e-12), 0.0).clip(0, 1)
    A = np.array([p[0] for p in pts])[seg]
    B = np.array([p[1] for p in pts])[seg]
    xy = A + (B - A) * frac[:, None]
    L0 = np.array([l[0] for l in lengths])[seg]
    L1 = np.array([l[1] for l in lengths])[seg]
    return t, xy, L0 + (L1 - L0) * frac, np.array(strip_id)[seg]


def simulate_flight(
    extent: tuple[float, float, float, float],
    camera: Camera,
    settings: FlightSettings,
    kite_offset: KiteOffset,
    ground_z: GroundZ,
    rng: np.random.Generator,
) -> FlightResult:
    """Simulate the walk, the camera's motion, the shots and the GPS logs.

    Returns truth (poses of the kept shots, continuous tracks) and observed GPS logs.

    Kept as one function (over ~80 lines) on purpose: its phases (jitter, pendulum, shot
    triggers, GPS errors) all draw from the one ``rng`` stream in a fixed order, and every
    twin's photos and logs depend on that order; a split would have to hand the stream on
    in exactly the same order, which one linear body makes plain to read and to keep.

    Parameters
    ----------
    extent : tuple of float
        Site extent ``(xmin, ymin, xmax, ymax)`` (m).
    camera : Camera
        The camera.
    settings : FlightSettings
        The flight settings.
    kite_offset : KiteOffset
        Kite position ``(downwind_m, height_m)`` relative to the operator's hand for a line length (m).
    ground_z : GroundZ
        Ground elevation (m) at map coordinates, for the operator's walk.
    rng : numpy.random.Generator
        The one random stream of the flight.

    Returns
    -------
    FlightResult
        Strips, poses of the kept shots, operator and camera tracks, their GPS logs, the number
        of triggers and a summary.
    """
    strips = plan_strips(extent, camera, settings, kite_offset)
    dt = settings.time_step_s
    t, op_xy, L, sid = _walk(strips, settings.walk_speed_m_s, dt)
    n = len(t)
    op_z = np.asarray(ground_z(op_xy[:, 0], op_xy[:, 1]), dtype=float)
    # kite offset along the way: exact at strip lengths, linear in L in between
    Ls = np.array(sorted(set(settings.line_lengths_m)))
    offs = np.array([kite_offset(v) for v in Ls])
    if len(Ls) == 1:
        down = np.full(n, offs[0, 0])
        up = np.full(n, offs[0, 1])
    else:
        down = np.interp(L, Ls, offs[:, 0])
        up = np.interp(L, Ls, offs[:, 1])
    jit = np.column_stack(
        [
            ou_process(rng, n, dt, settings.jitter_horizontal_m, settings.jitter_correlation_s),
            ou_process(rng, n, dt, settings.jitter_horizontal_m, settings.jitter_correlation_s),
            ou_process(rng, n, dt, settings.jitter_vertical_m, settings.jitter_correlation_s),
        ]
    )
    cam = np.column_stack(
        [
            op_xy + down[:, None] * settings.downwind_unit + jit[:, :2],
            op_z + settings.operator_hand_height_m + up - settings.rig_below_kite_m + jit[:, 2],
        ]
    )
    # pendulum: period 2π√(l/g); swinging amplitude itself drifts (gusts)
    period = 2 * np.pi * np.sqrt(settings.pendulum_length_m / settings.gravity_m_s2)
    w0 = 2 * np.pi / period
    amp = settings.tilt_amplitude_deg
    env = 0.75 + 0.25 * np.tanh(ou_process(rng, n, dt, 1.0, 20.0))
    ph = rng.uniform(0, 2 * np.pi, 2)
    omega = amp * env * np.sin(w0 * t + ph[0]) + ou_process(rng, n, dt, 0.3 * amp, 1.0)
    phi = amp * env * np.sin(w0 * 1.07 * t + ph[1]) + ou_process(rng, n, dt, 0.3 * amp, 1.0)
    yaw = settings.base_heading_deg + ou_process(rng, n, dt, settings.yaw_sd_deg, settings.yaw_correlation_s)

    # intervalometer: every trigger_interval_s from t=0, random phase of the first shot
    t_trig = np.arange(rng.uniform(0, settings.trigger_interval_s), t[-1], settings.trigger_interval_s)
    k_trig = np.clip(np.rint(t_trig / dt).astype(int), 0, n - 1)
    keep = np.zeros(len(k_trig), dtype=bool)
    trig_strip = sid[k_trig]
    for s in strips:
        idx = np.flatnonzero(trig_strip == s.index)
        keep[idx[:: s.keep_every]] = True
    # drop shots at the strip ends whose planned footprint barely touches the site
    heights = {s.index: s.height_m for s in strips}
    for j in np.flatnonzero(keep):
        k = k_trig[j]
        frac = footprint_site_fraction(camera, cam[k, :2], heights[int(sid[k])], yaw[k], extent)
        if frac < settings.min_site_fraction:
            keep[j] = False
    kept = k_trig[keep]

    rows = []
    for j, k in enumerate(kept):
        R = nadir_rotation(yaw[k], omega[k], phi[k])
        q = rotation_to_quaternion(R)
        when = settings.start_time + timedelta(seconds=float(t[k]))
        rows.append(
            dict(
                image=f"IMG_{j + 1:04d}.jpg",
                time_s=round(float(t[k]), 3),
                timestamp=when.isoformat(timespec="milliseconds"),
                strip=int(sid[k]),
                line_length_m=float(L[k]),
                x_m=cam[k, 0],
                y_m=cam[k, 1],
                z_m=cam[k, 2],
                heading_deg=yaw[k] % 360.0,
                omega_deg=omega[k],
                phi_deg=phi[k],
                qw=q[0],
                qx=q[1],
                qy=q[2],
                qz=q[3],
                operator_x_m=op_xy[k, 0],
                operator_y_m=op_xy[k, 1],
                operator_z_m=op_z[k],
                **_angular_velocity(yaw, omega, phi, cam, k, dt),
            )
        )
    poses = pd.DataFrame(rows)
    op_track = pd.DataFrame({"time_s": t, "x_m": op_xy[:, 0], "y_m": op_xy[:, 1], "z_m": op_z + settings.operator_hand_height_m})
    cam_track = pd.DataFrame({"time_s": t, "x_m": cam[:, 0], "y_m": cam[:, 1], "z_m": cam[:, 2]})
    op_gps = gps_log(op_track, settings, rng)
    cam_gps = gps_log(cam_track, settings, rng)
    summary = dict(
        n_strips=len(strips),
        n_triggers=int(len(k_trig)),
        n_images=int(len(kept)),
        flight_duration_s=float(t[-1]),
        strip_spacing_m=float(
            np.linalg.norm(((strips[1].start - strips[0].start) @ settings.across_unit) * settings.across_unit)
        ) if len(strips) > 1 else float("nan"),
        keep_every=[s.keep_every for s in strips],
    )
    return FlightResult(strips, poses, op_track, cam_track, op_gps, cam_gps, int(len(k_trig)), summary)


def _angular_velocity(yaw, omega, phi, cam, k, dt) -> dict[str, float]:
    """Camera velocity (m/s) and attitude rates (deg/s) at sample k (central differences)."""
    k0, k1 = max(k - 1, 0), min(k + 1, len(yaw) - 1)
    span = (k1 - k0) * dt
    v = (cam[k1] - cam[k0]) / span
    return dict(
        vx_m_s=v[0], vy_m_s=v[1], vz_m_s=v[2],
        heading_rate_deg_s=(yaw[k1] - yaw[k0]) / span,
        omega_rate_deg_s=(omega[k1] - omega[k0]) / span,
        phi_rate_deg_s=(phi[k1] - phi[k0]) / span,
    )


def pose_from_row(row: Mapping[str, Any], dt_s: float = 0.0) -> Pose:
    """Camera pose of a ``poses.csv`` row, optionally advanced by ``dt_s`` with its rates."""
    R = nadir_rotation(
        row["heading_deg"] + dt_s * row.get("heading_rate_deg_s", 0.0),
        row["omega_deg"] + dt_s * row.get("omega_rate_deg_s", 0.0),
        row["phi_deg"] + dt_s * row.get("phi_rate_deg_s", 0.0),
    )
    C = np.array([row["x_m"], row["y_m"], row["z_m"]], dtype=float)
    if dt_s:
        C = C + dt_s * np.array([row.get("vx_m_s", 0.0), row.get("vy_m_s", 0.0), row.get("vz_m_s", 0.0)])
    return Pose(R, C)


def gps_log(track: pd.DataFrame, settings: FlightSettings, rng: np.random.Generator) -> pd.DataFrame:
    """A GPS logger's record of a track: one fix every ``gps_interval_s`` with correlated noise.

    Parameters
    ----------
    track : DataFrame
        Track with ``time_s``, ``x_m``, ``y_m``, ``z_m``.
    settings : FlightSettings
        Gives ``gps_interval_s``, the noise (``gps_sigma_m``, ``gps_vertical_sigma_m``,
        ``gps_correlation_s``) and ``start_time``.
    rng : numpy.random.Generator
        Random stream.

    Returns
    -------
    DataFrame
        One row per fix: ``time_s``, ``timestamp`` (ISO), ``x_m``, ``y_m``, ``z_m``.
    """
    t = track["time_s"].to_numpy()
    tg = np.arange(0.0, t[-1] + 1e-9, settings.gps_interval_s)
    x = np.interp(tg, t, track["x_m"])
    y = np.interp(tg, t, track["y_m"])
    z = np.interp(tg, t, track["z_m"])
    dt = settings.gps_interval_s
    sig_h, sig_v, tau = settings.gps_sigma_m, settings.gps_vertical_sigma_m, settings.gps_correlation_s
    n = len(tg)
    return pd.DataFrame(
        {
            "time_s": tg,
            "timestamp": [(settings.start_time + timedelta(seconds=float(s))).isoformat() for s in tg],
            "x_m": x + ou_process(rng, n, dt, sig_h, tau),
            "y_m": y + ou_process(rng, n, dt, sig_h, tau),
            "z_m": z + ou_process(rng, n, dt, sig_v, tau),
        }
    )


def write_gpx(log: pd.DataFrame, crs: str, path: str | Path, name: str) -> None:
    """Write a GPS log (site CRS) as a GPX 1.1 track in WGS84.

    Parameters
    ----------
    log : DataFrame
        GPS log with ``x_m``, ``y_m``, ``z_m`` and ``timestamp`` (UTC, no zone), as from :func:`gps_log`.
    crs : str
        CRS of ``x_m`` and ``y_m``.
    path : str or Path
        The GPX file; its parent folder is created.
    name : str
        Track name.
    """
    from pyproj import Transformer

    tr = Transformer.from_crs(crs, "EPSG:4326", always_xy=True)
    lon, lat = tr.transform(log["x_m"].to_numpy(), log["y_m"].to_numpy())
    pts = "\n".join(
        f'      <trkpt lat="{la:.8f}" lon="{lo:.8f}"><ele>{z:.2f}</ele><time>{ts}Z</time></trkpt>'
        for la, lo, z, ts in zip(lat, lon, log["z_m"], log["timestamp"])
    )
    text = (
        '<?xml version="1.0" encoding="UTF-8"?>\n'
        '<gpx version="1.1" creator="kitegully" xmlns="http://www.topografix.com/GPX/1/1">\n'
        f"  <trk><name>{escape(name)}</name>\n    <trkseg>\n{pts}\n    </trkseg>\n  </trk>\n</gpx>\n"
    )
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    Path(path).write_text(text, encoding="utf-8")


def read_extent(path: str | Path) -> tuple[float, float, float, float]:
    """Site extent ``(xmin, ymin, xmax, ymax)`` from the twin's ``site.json``."""
    import json

    try:
        d = json.loads(Path(path).read_text(encoding="utf-8"))
        e = d.get("extent", d)
        ext = (float(e["xmin"]), float(e["ymin"]), float(e["xmax"]), float(e["ymax"]))
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise InputError(f"{path}: cannot read the site extent (xmin, ymin, xmax, ymax): {exc}") from None
    if ext[2] <= ext[0] or ext[3] <= ext[1]:
        raise InputError(f"{path}: site extent is empty or inverted: {ext}")
    return ext


def tether_kite_offset(tether_cfg: Mapping[str, Any], material: str, kite: str, wind_m_s: float) -> KiteOffset:
    """Kite position for a line length from the tether model (``kitegully.tether.line``).

    Parameters
    ----------
    tether_cfg : mapping
        The ``tether`` config section; ``segment_length_m`` (m, default 1) is the integration step.
    material : str
        Name of a line of ``tether.lines``.
    kite : str
        Name of a kite of ``tether.kites``.
    wind_m_s : float
        Wind speed (m/s).

    Returns
    -------
    KiteOffset
        Function of the line length (m) giving the kite's ``(downwind_m, height_m)``; it raises
        InputError when the kite does not fly at that length.
    """
    from kitegully.tether.config import tether_from_config
    from kitegully.tether.line import FlightStatus, kite_position

    materials, kites, atmosphere = tether_from_config(tether_cfg)
    if material not in materials:
        raise InputError(f"flight.material: '{material}' is not a line of tether.lines ({', '.join(materials)})")
    if kite not in kites:
        raise InputError(f"flight.kite: '{kite}' is not a kite of tether.kites ({', '.join(kites)})")
    ds = float(tether_cfg.get("segment_length_m", 1.0))

    def offset(line_length_m: float) -> tuple[float, float]:
        pos = kite_position(materials[material], kites[kite], wind_m_s, line_length_m, atmosphere, ds)
        if pos.status is not FlightStatus.FLYING:
            raise InputError(f"flight.line_lengths_m: with {line_length_m:g} m of {material} at {wind_m_s:g} m/s "
                             f"the tether model says '{pos.status.value}'")
        return float(pos.downwind_m), float(pos.height_m)

    return offset
