"""Quasi-static model of a kite line in a uniform horizontal wind.

The line is cut into segments of length ``ds`` (1 m in Feurer et al. 2018). Walking down
from the kite, each segment at local elevation angle θ carries its weight ``μ·g·ds`` and the
pressure drag of a cylinder in the wind component normal to it,
``dF = ½·ρ·(d·ds)·Cx_line·(V·sinθ)²``, acting along the normal (sinθ, −cosθ), i.e.
downwind and downward. With x downwind and z up, the tension below a segment is::

    T_lower = T_upper + (dF·sinθ, −dF·cosθ − μ·g·ds)

The top tension comes from the kite. Two readings of the paper's undefined "pull angle"
are implemented (``../shared/METHODS.md`` sect. 1.2):

``bridle_tension`` ([I-A], default)
    The line tension at the bridle has elevation ``pull_angle``; the kite's weight is
    already included: ``T_top = Dk·(1, tan(pull))`` with ``Dk = ½·ρ·A·V²·Cx_wing``.
``aero_resultant`` ([I-B])
    The aerodynamic resultant points at ``pull_angle``; wing and payload weight are then
    subtracted: ``T_top = (Dk, Dk·tan(pull) − (m_wing + m_payload)·g)``.

Because the top boundary condition does not depend on the line length, one integration
from the kite down to the longest line gives the solution for every shorter length at once:
the operator holds the line at node ``k`` for a line of ``k·ds`` metres. Where the vertical
tension reaches zero the rest of the line lies on the ground.

Each step is second order (midpoint rule on θ). Cost: O(n_steps × n_cases), vectorised over
cases (winds, materials).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

import numpy as np

GRAVITY = 9.81


class KiteModel(str, Enum):
    """Reading of the paper's pull angle (see module docstring)."""

    BRIDLE_TENSION = "bridle_tension"
    AERO_RESULTANT = "aero_resultant"


class FlightStatus(str, Enum):
    """Outcome for one (material, wind, line length)."""

    FLYING = "flying"
    LINE_ON_GROUND = "line_on_ground"
    CANNOT_FLY = "cannot_fly"


@dataclass(frozen=True)
class LineMaterial:
    """A kite line (Feurer et al. 2018, Table 1).

    Attributes
    ----------
    name : str
    diameter_m : float
        Line diameter (m).
    linear_mass_kg_m : float
        Mass per metre (kg/m).
    breaking_load_n : float or None
        Rated strength (N), for the tension check; None when not rated.
    drag_coefficient : float
        Cylinder drag coefficient of the line (1.0 in the paper).
    """

    name: str
    diameter_m: float
    linear_mass_kg_m: float
    breaking_load_n: float | None = None
    drag_coefficient: float = 1.0


@dataclass(frozen=True)
class Kite:
    """A kite and its rig.

    Attributes
    ----------
    name : str
    area_m2 : float
        Reference area A in ``½·ρ·A·V²·Cx`` (8.7 m² for the 10 m² delta).
    drag_coefficient : float
        Cx of the wing (0.15).
    pull_angle_deg : float
        Elevation of the pull (60°); meaning set by :class:`KiteModel`.
    wing_mass_kg, payload_mass_kg : float
        Used only by the ``aero_resultant`` reading.
    model : KiteModel
    """

    name: str
    area_m2: float
    drag_coefficient: float
    pull_angle_deg: float
    wing_mass_kg: float = 0.0
    payload_mass_kg: float = 0.0
    model: KiteModel = KiteModel.BRIDLE_TENSION


@dataclass(frozen=True)
class Atmosphere:
    """Air density (kg/m³) and gravity (m/s²)."""

    air_density_kg_m3: float = 1.18
    gravity_m_s2: float = GRAVITY


@dataclass(frozen=True)
class KitePosition:
    """Kite relative to the operator's hand for one line length.

    ``downwind_m``, ``height_m`` and ``flight_angle_deg`` are NaN unless ``status`` is
    ``FLYING``; ``grounded_length_m`` is the length lying on the ground.
    """

    downwind_m: float
    height_m: float
    flight_angle_deg: float
    status: FlightStatus
    grounded_length_m: float = 0.0


@dataclass(frozen=True)
class LineSolution:
    """Line integrated from the kite downwards, for every wind of a sweep.

    Node 0 is the kite; node k is ``k·ds`` metres of line below it. Coordinates are relative
    to the kite (x downwind, z up), so all x, z ≤ 0 below the kite.

    Attributes
    ----------
    winds_m_s : (n_wind,) array
    ds_m : float
    x, z : (n_wind, n_nodes) arrays
        Node positions relative to the kite (m). NaN below the touchdown node.
    tension : (n_wind, n_nodes, 2) array
        Tension (Tx, Tz) in N just below each node.
    touchdown_node : (n_wind,) int array
        First node where the vertical tension is ≤ 0 (the line lies on the ground from
        there), or ``n_nodes`` when the whole line is airborne.
    can_fly : (n_wind,) bool array
        False where the kite cannot lift the line at all (vertical tension at the bridle ≤ 0).
    """

    winds_m_s: np.ndarray
    ds_m: float
    x: np.ndarray
    z: np.ndarray
    tension: np.ndarray
    touchdown_node: np.ndarray
    can_fly: np.ndarray

    @property
    def n_nodes(self) -> int:
        """Number of nodes along the line, the kite's included."""
        return self.x.shape[1]

    def position(self, wind_index: int, line_length_m: float) -> KitePosition:
        """Kite position relative to the operator for one wind and line length."""
        return positions_for_lengths(self, np.array([line_length_m]))[wind_index][0]

    def shape(self, wind_index: int, line_length_m: float) -> tuple[np.ndarray, np.ndarray]:
        """Line nodes from the operator (0, 0) to the kite, airborne part only.

        Raises
        ------
        ValueError
            If the kite cannot fly or part of the line lies on the ground.
        """
        pos = self.position(wind_index, line_length_m)
        if pos.status is not FlightStatus.FLYING:
            raise ValueError(
                f"no line shape at {self.winds_m_s[wind_index]:g} m/s and {line_length_m:g} m: {pos.status.value}"
            )
        k = _node_index(line_length_m, self.ds_m)
        xs = self.x[wind_index, : k + 1][::-1] - self.x[wind_index, k]
        zs = self.z[wind_index, : k + 1][::-1] - self.z[wind_index, k]
        return xs, zs


def kite_drag_n(kite: Kite, wind_m_s: np.ndarray, atmosphere: Atmosphere) -> np.ndarray:
    """Horizontal kite force ``Dk = ½·ρ·A·V²·Cx_wing`` (N).

    Parameters
    ----------
    kite : Kite
        Gives the area A and Cx of the wing.
    wind_m_s : ndarray
        Wind speeds V (m/s).
    atmosphere : Atmosphere
        Gives the air density ρ.

    Returns
    -------
    ndarray
        Dk (N) for each wind speed.
    """
    v = np.asarray(wind_m_s, dtype=float)
    return 0.5 * atmosphere.air_density_kg_m3 * kite.area_m2 * v**2 * kite.drag_coefficient


def top_tension(kite: Kite, wind_m_s: np.ndarray, atmosphere: Atmosphere) -> np.ndarray:
    """Tension (Tx, Tz) at the bridle for each wind, shape (n_wind, 2).

    Parameters
    ----------
    kite : Kite
        The kite; its ``model`` sets the reading of the pull angle.
    wind_m_s : ndarray
        Wind speeds (m/s).
    atmosphere : Atmosphere
        Air density and gravity.

    Returns
    -------
    ndarray (n_wind, 2)
        Tx = Dk and Tz = Dk·tan(pull), less the wing and payload weight under ``aero_resultant`` (N).
    """
    dk = kite_drag_n(kite, wind_m_s, atmosphere)
    tz = dk * np.tan(np.radians(kite.pull_angle_deg))
    if kite.model is KiteModel.AERO_RESULTANT:
        tz = tz - (kite.wing_mass_kg + kite.payload_mass_kg) * atmosphere.gravity_m_s2
    return np.stack([dk, tz], axis=-1)


def _segment_load(theta: np.ndarray, wind: np.ndarray, material: LineMaterial, ds: float, atm: Atmosphere):
    """Increment (dTx, dTz) of the tension across one segment at elevation ``theta``."""
    s, c = np.sin(theta), np.cos(theta)
    drag = 0.5 * atm.air_density_kg_m3 * material.diameter_m * ds * material.drag_coefficient * (wind * s) ** 2
    weight = material.linear_mass_kg_m * atm.gravity_m_s2 * ds
    return drag * s, -drag * c - weight


def solve_line(
    material: LineMaterial,
    kite: Kite,
    winds_m_s: np.ndarray | list[float],
    max_length_m: float,
    atmosphere: Atmosphere = Atmosphere(),
    ds_m: float = 1.0,
) -> LineSolution:
    """Integrate the line from the kite down to ``max_length_m`` for every wind.

    Parameters
    ----------
    material, kite, atmosphere
        Line, kite and air properties.
    winds_m_s
        Uniform horizontal wind speeds (m/s).
    max_length_m
        Longest line of interest (m); every shorter length is read from the same solution.
    ds_m
        Segment length (m).

    Returns
    -------
    LineSolution

    Notes
    -----
    Complexity O(max_length_m/ds_m × n_wind) time and memory.
    """
    winds = np.atleast_1d(np.asarray(winds_m_s, dtype=float))
    if np.any(winds <= 0):
        raise ValueError("wind speeds must be positive")
    if ds_m <= 0 or max_length_m < 0:
        raise ValueError("segment length must be positive and line length non-negative")
    n_steps = int(round(max_length_m / ds_m))
    n_nodes = n_steps + 1
    x = np.full((winds.size, n_nodes), np.nan)
    z = np.full((winds.size, n_nodes), np.nan)
    tension = np.full((winds.size, n_nodes, 2), np.nan)
    t = top_tension(kite, winds, atmosphere)
    can_fly = t[:, 1] > 0
    x[:, 0] = 0.0
    z[:, 0] = 0.0
    tension[:, 0] = t
    airborne = can_fly.copy()
    touchdown = np.where(can_fly, n_nodes, 0)
    for k in range(n_steps):
        theta_u = np.arctan2(t[:, 1], t[:, 0])
        dtx, dtz = _segment_load(theta_u, winds, material, ds_m, atmosphere)
        theta_m = np.arctan2(t[:, 1] + 0.5 * dtz, t[:, 0] + 0.5 * dtx)
        dtx, dtz = _segment_load(theta_m, winds, material, ds_m, atmosphere)
        x[:, k + 1] = np.where(airborne, x[:, k] - ds_m * np.cos(theta_m), np.nan)
        z[:, k + 1] = np.where(airborne, z[:, k] - ds_m * np.sin(theta_m), np.nan)
        t = t + np.stack([dtx, dtz], axis=-1)
        tension[:, k + 1] = np.where(airborne[:, None], t, np.nan)
        grounded_now = airborne & (t[:, 1] <= 0)
        touchdown[grounded_now] = k + 1
        airborne &= ~grounded_now
    return LineSolution(winds, ds_m, x, z, tension, touchdown, can_fly)


def _node_index(line_length_m: float, ds_m: float) -> int:
    return int(round(line_length_m / ds_m))


def positions_for_lengths(solution: LineSolution, lengths_m: np.ndarray) -> list[list[KitePosition]]:
    """Kite positions for every wind of ``solution`` and every line length.

    Returns a list (per wind) of lists (per length) of :class:`KitePosition`.
    """
    out: list[list[KitePosition]] = []
    for w in range(solution.winds_m_s.size):
        row = []
        for length in np.asarray(lengths_m, dtype=float):
            k = _node_index(length, solution.ds_m)
            if k >= solution.n_nodes:
                raise ValueError(f"line length {length} m beyond the solved {solution.ds_m * (solution.n_nodes - 1)} m")
            if not solution.can_fly[w]:
                row.append(KitePosition(np.nan, np.nan, np.nan, FlightStatus.CANNOT_FLY, float(length)))
            elif k >= solution.touchdown_node[w]:
                grounded = (k - solution.touchdown_node[w]) * solution.ds_m
                row.append(KitePosition(np.nan, np.nan, np.nan, FlightStatus.LINE_ON_GROUND, float(grounded)))
            elif k == 0:
                row.append(KitePosition(0.0, 0.0, np.nan, FlightStatus.FLYING))
            else:
                dx = -solution.x[w, k]
                dz = -solution.z[w, k]
                row.append(KitePosition(dx, dz, float(np.degrees(np.arctan2(dz, dx))), FlightStatus.FLYING))
        out.append(row)
    return out


def kite_position(
    material: LineMaterial,
    kite: Kite,
    wind_m_s: float,
    line_length_m: float,
    atmosphere: Atmosphere = Atmosphere(),
    ds_m: float = 1.0,
) -> KitePosition:
    """Kite position relative to the operator for one wind and line length.

    For many lengths at the same wind, call :func:`solve_line` once and use
    :func:`positions_for_lengths` instead (one integration serves all lengths).

    Parameters
    ----------
    material : LineMaterial
        The line.
    kite : Kite
        The kite.
    wind_m_s : float
        Uniform horizontal wind speed (m/s).
    line_length_m : float
        Line length (m).
    atmosphere : Atmosphere
        Air density and gravity.
    ds_m : float
        Segment length (m).

    Returns
    -------
    KitePosition
    """
    sol = solve_line(material, kite, [wind_m_s], line_length_m, atmosphere, ds_m)
    return sol.position(0, line_length_m)


def line_length_for_height(solution: LineSolution, wind_index: int, height_m: float) -> float:
    """Shortest line length (m) that puts the kite ``height_m`` above the operator.

    Interpolates the kite height along the solved line. Returns NaN when the height is not
    reached before the line touches the ground or the solved length ends.

    Parameters
    ----------
    solution : LineSolution
        The solved line.
    wind_index : int
        Index of the wind in ``solution.winds_m_s``.
    height_m : float
        Kite height above the operator (m).

    Returns
    -------
    float
        Line length (m); 0 when ``height_m`` ≤ 0, NaN when the height is not reached or the kite cannot fly.
    """
    if not solution.can_fly[wind_index]:
        return float("nan")
    last = min(solution.touchdown_node[wind_index], solution.n_nodes) - 1
    z = solution.z[wind_index, : last + 1]
    # Height of the kite above the operator at node k is -z[k]; it increases with k.
    h = -z
    idx = np.searchsorted(h, height_m)
    if idx == 0:
        return 0.0 if height_m <= 0 else float("nan")
    if idx > last:
        return float("nan")
    frac = (height_m - h[idx - 1]) / (h[idx] - h[idx - 1])
    return float((idx - 1 + frac) * solution.ds_m)
