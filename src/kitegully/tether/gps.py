"""Effective flight angles from paired camera and operator GPS logs (Feurer et al. 2018 Fig. 7).

Both loggers record at 1 Hz. A fix pair taken at the same second gives the chord elevation
``α = atan2(z_cam − z_op, horizontal distance)``. Logs are GPX 1.0/1.1 tracks (WGS84) or CSV
with a ``time`` column and either ``lat, lon, ele`` (WGS84) or ``x, y, z`` (site CRS).

The module also writes synthetic logs for twin sites: the operator walks a straight path,
the kite sits where the line model puts it for a gusty wind, and both positions get GPS noise.
So that Fig. 7 on a twin tests something, the simulation can add what the quasi-static line
model lacks: the kite's lag behind gusts, the camera's pendulum swing below the kite, and the
operator's varying walking speed (apparent wind).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from pyproj import Transformer

from kitegully import InputError
from kitegully.tether.line import Atmosphere, Kite, LineMaterial, positions_for_lengths, solve_line

WGS84 = "EPSG:4326"


# --------------------------------------------------------------------------------------
# Reading
# --------------------------------------------------------------------------------------


def _parse_gpx(path: Path) -> pd.DataFrame:
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise InputError(f"{path}: not a valid GPX/XML file ({exc})") from None
    ns = root.tag.split("}")[0] + "}" if root.tag.startswith("{") else ""
    rows = []
    for pt in root.iter(f"{ns}trkpt"):
        ele = pt.find(f"{ns}ele")
        time = pt.find(f"{ns}time")
        if time is None or ele is None:
            raise InputError(f"{path}: a track point has no <time> or <ele>; flight angles need both")
        rows.append((time.text, float(pt.attrib["lat"]), float(pt.attrib["lon"]), float(ele.text)))
    if not rows:
        raise InputError(f"{path}: no track points (<trkpt>) found")
    return pd.DataFrame(rows, columns=["time", "lat", "lon", "ele"])


def read_track(path: str | Path, crs: str) -> pd.DataFrame:
    """Read a GPS log and return columns ``time`` (UTC, whole seconds), ``x, y, z`` in ``crs``.

    Parameters
    ----------
    path
        GPX file or CSV (``time`` plus ``lat, lon, ele`` or ``x, y, z``).
    crs
        Projected site CRS (metres) to express the positions in.

    Raises
    ------
    InputError
        Unreadable file, missing columns, unparsable times, or duplicate timestamps.
    """
    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: GPS log not found")
    if path.suffix.lower() == ".gpx":
        df = _parse_gpx(path)
    else:
        try:
            df = pd.read_csv(path)
        except Exception as exc:
            raise InputError(f"{path}: cannot read CSV ({exc})") from None
    cols = set(df.columns)
    if "time" not in cols:
        raise InputError(f"{path}: GPS log has no 'time' column")
    try:
        time = pd.to_datetime(df["time"], utc=True)
    except (ValueError, TypeError) as exc:
        raise InputError(f"{path}: cannot parse the 'time' column ({exc})") from None
    if {"lat", "lon", "ele"} <= cols:
        tr = Transformer.from_crs(WGS84, crs, always_xy=True)
        x, y = tr.transform(df["lon"].to_numpy(float), df["lat"].to_numpy(float))
        z = df["ele"].to_numpy(float)
    elif {"x", "y", "z"} <= cols:
        x, y, z = (df[c].to_numpy(float) for c in ("x", "y", "z"))
    else:
        raise InputError(f"{path}: GPS log needs columns lat, lon, ele or x, y, z (has {sorted(cols)})")
    out = pd.DataFrame({"time": time.dt.round("1s"), "x": x, "y": y, "z": z})
    if out["time"].duplicated().any():
        raise InputError(f"{path}: several fixes share one second; expected a 1 Hz log")
    if not np.all(np.isfinite(out[["x", "y", "z"]].to_numpy())):
        raise InputError(f"{path}: some positions are not finite numbers")
    return out.sort_values("time").reset_index(drop=True)


# --------------------------------------------------------------------------------------
# Flight angles
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class LineSchedule:
    """Line lengths paid out during a flight: ``lengths_m[i]`` from ``start_s[i]`` on.

    Times are seconds after the first paired fix. Fixes within ``settle_s`` after a change
    are dropped, since the kite is still climbing to its new position.
    """

    start_s: tuple[float, ...]
    lengths_m: tuple[float, ...]
    settle_s: float = 30.0

    def length_at(self, elapsed_s: np.ndarray) -> np.ndarray:
        """Line length paid out at each elapsed time.

        Parameters
        ----------
        elapsed_s : ndarray
            Seconds after the first paired fix.

        Returns
        -------
        ndarray
            Line length (m); NaN before the first step and within ``settle_s`` after each later change.
        """
        idx = np.searchsorted(np.asarray(self.start_s), elapsed_s, side="right") - 1
        lengths = np.where(idx >= 0, np.asarray(self.lengths_m)[np.clip(idx, 0, None)], np.nan)
        since = elapsed_s - np.asarray(self.start_s)[np.clip(idx, 0, None)]
        settling = (since < self.settle_s) & (idx > 0)
        return np.where(settling, np.nan, lengths)


def flight_angles(camera: pd.DataFrame, operator: pd.DataFrame, schedule: LineSchedule) -> pd.DataFrame:
    """Pair camera and operator fixes by timestamp and compute the effective flight angle.

    Parameters
    ----------
    camera, operator : DataFrame
        The two logs as :func:`read_track` returns them: ``time`` and ``x, y, z`` (m, site CRS).
    schedule : LineSchedule
        Line lengths paid out, timed from the first paired fix.

    Returns
    -------
    pandas.DataFrame
        Columns ``time, elapsed_s, line_length_m, horizontal_distance_m, height_m,
        flight_angle_deg``, one row per paired second with a known (settled) line length.

    Raises
    ------
    InputError
        When the two logs share no timestamp.
    """
    pairs = camera.merge(operator, on="time", suffixes=("_cam", "_op"))
    if pairs.empty:
        raise InputError("the camera and operator logs share no timestamp (check time zones and clocks)")
    elapsed = (pairs["time"] - pairs["time"].iloc[0]).dt.total_seconds().to_numpy()
    dx = pairs["x_cam"] - pairs["x_op"]
    dy = pairs["y_cam"] - pairs["y_op"]
    dz = pairs["z_cam"] - pairs["z_op"]
    horiz = np.hypot(dx, dy)
    out = pd.DataFrame(
        {
            "time": pairs["time"],
            "elapsed_s": elapsed,
            "line_length_m": schedule.length_at(elapsed),
            "horizontal_distance_m": horiz,
            "height_m": dz,
            "flight_angle_deg": np.degrees(np.arctan2(dz, horiz)),
        }
    )
    return out.dropna(subset=["line_length_m"]).reset_index(drop=True)


def summarise_flight_angles(angles: pd.DataFrame) -> pd.DataFrame:
    """Per flight and line length: n, min, p05, median, mean, p95, max of the flight angle (°).

    ``angles`` needs columns ``flight, kite, line_length_m, flight_angle_deg``.
    """
    g = angles.groupby(["flight", "kite", "line_length_m"], sort=True)["flight_angle_deg"]
    summary = g.agg(
        n="size",
        min_deg="min",
        p05_deg=lambda s: s.quantile(0.05),
        median_deg="median",
        mean_deg="mean",
        p95_deg=lambda s: s.quantile(0.95),
        max_deg="max",
    )
    return summary.reset_index()


# --------------------------------------------------------------------------------------
# Synthetic logs
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class SyntheticFlight:
    """One simulated flight for a twin site's GPS logs."""

    name: str
    kite: Kite
    material: LineMaterial
    mean_wind_m_s: float
    gust_sd_m_s: float
    gust_time_constant_s: float
    schedule: LineSchedule
    duration_s: int
    start_time: str


@dataclass(frozen=True)
class SyntheticLogSettings:
    """Geometry and noise of the synthetic logs (all distances in m, azimuths in degrees)."""

    origin_x: float
    origin_y: float
    ground_z: float
    walk_azimuth_deg: float
    wind_to_azimuth_deg: float
    walking_speed_m_s: float
    rig_drop_m: float
    gps_horizontal_sd_m: float
    gps_vertical_sd_m: float
    #: Effects the quasi-static line model does not have (0 = off). The kite follows its
    #: equilibrium position for the current wind with a first-order lag of this time
    #: constant (s) instead of jumping to it.
    kite_response_s: float = 0.0
    #: RMS swing angle (degrees) of the camera on its pendulum of length ``rig_drop_m``
    #: below the kite: a narrow-band random swing at the natural period 2π√(L/g).
    pendulum_rms_deg: float = 0.0
    #: SD (m/s) of the operator's walking speed around ``walking_speed_m_s`` (AR(1) with
    #: the gust time constant, stops at 0): the kite flies in the wind relative to the
    #: walking operator, so the line model is evaluated at the apparent wind.
    walking_speed_sd_m_s: float = 0.0


def _ar1(mean: float, sd: float, tau: float, n: int, rng: np.random.Generator) -> np.ndarray:
    """AR(1) series at 1 Hz with mean ``mean``, standard deviation ``sd`` and time constant ``tau``."""
    if sd <= 0 or n == 0:
        return np.full(n, float(mean))
    phi = math.exp(-1.0 / max(tau, 1e-6))
    e = rng.normal(0.0, sd * math.sqrt(1 - phi**2), n)
    g = np.empty(n)
    g[0] = rng.normal(0.0, sd)
    for i in range(1, n):
        g[i] = phi * g[i - 1] + e[i]
    return mean + g


def _gusty_wind(mean: float, sd: float, tau: float, n: int, rng: np.random.Generator) -> np.ndarray:
    """AR(1) wind speed series at 1 Hz with standard deviation ``sd`` and time constant ``tau`` (≥ 0.5 m/s)."""
    return np.maximum(_ar1(mean, sd, tau, n, rng), 0.5)


def _lag(x: np.ndarray, tau: float) -> np.ndarray:
    """First-order lag (time constant ``tau`` s) of a 1 Hz series; NaN (line on the ground) passes through."""
    a = 1.0 - math.exp(-1.0 / tau)
    out = np.array(x, dtype=float)
    for i in range(1, out.size):
        if np.isfinite(out[i]) and np.isfinite(out[i - 1]):
            out[i] = out[i - 1] + a * (x[i] - out[i - 1])
    return out


def _pendulum(length_m: float, rms_deg: float, n: int, rng: np.random.Generator, damping: float = 0.1,
              dt: float = 0.05) -> np.ndarray:
    """Swing angle (rad) at 1 Hz of a randomly forced damped pendulum of ``length_m``, RMS ``rms_deg``.

    θ'' + 2ζω₀θ' + ω₀²θ = white noise, ω₀ = √(g/L), integrated at ``dt`` (semi-implicit
    Euler) and rescaled to the RMS; O(n/dt).
    """
    w0 = math.sqrt(9.81 / length_m)
    k = int(round(1.0 / dt))
    f = rng.normal(0.0, 1.0, n * k)
    th = np.empty(n * k)
    x = v = 0.0
    for i in range(n * k):
        v += dt * (-2.0 * damping * w0 * v - w0 * w0 * x + f[i] / math.sqrt(dt))
        x += dt * v
        th[i] = x
    th = th[::k]
    sd = float(th.std())
    return th * (math.radians(rms_deg) / sd) if sd > 0 else th


def simulate_flight_logs(
    flight: SyntheticFlight,
    settings: SyntheticLogSettings,
    atmosphere: Atmosphere,
    rng: np.random.Generator,
    wind_step_m_s: float = 0.25,
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Camera and operator logs (time, x, y, z in the site CRS) for one flight.

    The kite's chord geometry is taken from the line model on a wind grid of
    ``wind_step_m_s`` and interpolated, so a 1 Hz flight of an hour costs a few line
    integrations. Seconds at which the kite could not keep the line off the ground are
    left out of the camera log (the logger still runs, but the camera is not where the
    model can say).

    Parameters
    ----------
    flight : SyntheticFlight
        Kite, line, wind, line schedule, duration and start time of the flight.
    settings : SyntheticLogSettings
        Geometry and noise of the logs.
    atmosphere : Atmosphere
        Air density and gravity.
    rng : Generator
        Draws the gusts, the walking speed, the pendulum swing and the GPS noise.
    wind_step_m_s : float
        Spacing of the wind grid the line model is solved on (m/s).

    Returns
    -------
    camera : DataFrame
        Camera log, seconds with the line off the ground only.
    operator : DataFrame
        Operator log, every second.
    """
    n = int(flight.duration_s)
    t = np.arange(n, dtype=float)
    wind = _gusty_wind(flight.mean_wind_m_s, flight.gust_sd_m_s, flight.gust_time_constant_s, n, rng)
    walk = math.radians(settings.walk_azimuth_deg)
    wto = math.radians(settings.wind_to_azimuth_deg)
    speed = np.full(n, settings.walking_speed_m_s)
    if settings.walking_speed_sd_m_s > 0:
        speed = np.maximum(_ar1(settings.walking_speed_m_s, settings.walking_speed_sd_m_s,
                                flight.gust_time_constant_s, n, rng), 0.0)
        # apparent wind at the kite: the operator walking downwind slackens the line
        wind = np.maximum(wind - speed * math.cos(walk - wto), 0.5)
    lengths = np.asarray(flight.schedule.lengths_m, dtype=float)
    grid = np.arange(max(0.5, wind.min() - wind_step_m_s), wind.max() + 2 * wind_step_m_s, wind_step_m_s)
    sol = solve_line(flight.material, flight.kite, grid, float(lengths.max()), atmosphere)
    pos = positions_for_lengths(sol, lengths)
    down = np.array([[p.downwind_m for p in row] for row in pos])  # (n_wind, n_length)
    up = np.array([[p.height_m for p in row] for row in pos])
    idx = np.searchsorted(np.asarray(flight.schedule.start_s), t, side="right") - 1
    idx = np.clip(idx, 0, lengths.size - 1)
    d = np.empty(n)
    h = np.empty(n)
    for j in range(lengths.size):
        sel = idx == j
        d[sel] = np.interp(wind[sel], grid, down[:, j])
        h[sel] = np.interp(wind[sel], grid, up[:, j])
    if settings.kite_response_s > 0:
        d, h = _lag(d, settings.kite_response_s), _lag(h, settings.kite_response_s)
    s = np.concatenate([[0.0], np.cumsum(speed[:-1])])  # 1 s steps
    ox = settings.origin_x + s * math.sin(walk)
    oy = settings.origin_y + s * math.cos(walk)
    oz = np.full(n, settings.ground_z + 1.0)  # logger held at hand height
    cx = ox + d * math.sin(wto)
    cy = oy + d * math.cos(wto)
    cz = oz + h - settings.rig_drop_m
    if settings.pendulum_rms_deg > 0 and settings.rig_drop_m > 0:
        th_a, th_c = (_pendulum(settings.rig_drop_m, settings.pendulum_rms_deg, n, rng) for _ in range(2))
        L = settings.rig_drop_m
        cx = cx + L * (np.sin(th_a) * math.sin(wto) + np.sin(th_c) * math.cos(wto))
        cy = cy + L * (np.sin(th_a) * math.cos(wto) - np.sin(th_c) * math.sin(wto))
        cz = cz + L * (2.0 - np.cos(th_a) - np.cos(th_c))
    start = pd.Timestamp(flight.start_time)
    start = start.tz_localize("UTC") if start.tzinfo is None else start.tz_convert("UTC")
    times = start + pd.to_timedelta(t, unit="s")

    def noisy(x, y, z):
        return (
            x + rng.normal(0, settings.gps_horizontal_sd_m, n),
            y + rng.normal(0, settings.gps_horizontal_sd_m, n),
            z + rng.normal(0, settings.gps_vertical_sd_m, n),
        )

    ox_n, oy_n, oz_n = noisy(ox, oy, oz)
    cx_n, cy_n, cz_n = noisy(cx, cy, cz)
    operator = pd.DataFrame({"time": times, "x": ox_n, "y": oy_n, "z": oz_n})
    camera = pd.DataFrame({"time": times, "x": cx_n, "y": cy_n, "z": cz_n})
    airborne = np.isfinite(d) & np.isfinite(h)
    return camera[airborne].reset_index(drop=True), operator


def write_gpx(track: pd.DataFrame, path: str | Path, crs: str, name: str) -> None:
    """Write a track (time, x, y, z in ``crs``) as a GPX 1.1 file in WGS84.

    Parameters
    ----------
    track : DataFrame
        Columns ``time``, ``x, y`` (in ``crs``) and ``z`` (m), written as the elevation.
    path : str or Path
        Output file; missing parent folders are created.
    crs : str
        CRS of ``x, y``.
    name : str
        Track name written in the file.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tr = Transformer.from_crs(crs, WGS84, always_xy=True)
    lon, lat = tr.transform(track["x"].to_numpy(), track["y"].to_numpy())
    gpx = ET.Element("gpx", version="1.1", creator="kitegully", xmlns="http://www.topografix.com/GPX/1/1")
    trk = ET.SubElement(gpx, "trk")
    ET.SubElement(trk, "name").text = name
    seg = ET.SubElement(trk, "trkseg")
    for la, lo, z, tm in zip(lat, lon, track["z"].to_numpy(), track["time"]):
        pt = ET.SubElement(seg, "trkpt", lat=f"{la:.8f}", lon=f"{lo:.8f}")
        ET.SubElement(pt, "ele").text = f"{z:.2f}"
        ET.SubElement(pt, "time").text = pd.Timestamp(tm).strftime("%Y-%m-%dT%H:%M:%SZ")
    ET.ElementTree(gpx).write(path, xml_declaration=True, encoding="utf-8")
