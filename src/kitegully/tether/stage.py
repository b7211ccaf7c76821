"""The tether stage's products, one function per rule (Feurer et al. 2018 sect. 2.2-2.3).

:func:`simulate_tether` makes the flight angle table, the line shapes of Fig. 5 and the
Table 2 comparison (rule ``tether_simulation``); :func:`plan_flights` makes the flight
plan and the line lengths the model needs per material (rule ``tether_plan``). Every entry
point takes one :class:`TetherParams`, built by :meth:`TetherParams.from_config` from the
keys of the ``tether:`` config section its rule passes (see the rules' ``params``).
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from kitegully.tether.analysis import flight_angle_table, line_lengths_for_heights, table2_comparison
from kitegully.config import config_section
from kitegully.tether.config import (
    atmosphere_from_config,
    kites_from_config,
    materials_from_config,
    planning_camera_from_config,
    schedule_from_config,
    sweep_lengths,
    synthetic_flights_from_config,
)
from kitegully.tether.gps import flight_angles, read_track, simulate_flight_logs, summarise_flight_angles
from kitegully import InputError
from kitegully.tether.gps import LineSchedule, SyntheticFlight, SyntheticLogSettings
from kitegully.tether.line import Atmosphere, Kite, KiteModel, LineMaterial, solve_line
from kitegully.tether.planning import PlanningCamera, plan_flight
from kitegully.seeds import rng_for

log = logging.getLogger(__name__)

#: ``tether:`` keys read by :func:`simulate_tether`.
SIMULATION_KEYS = ("lines", "kites", "kite_model", "simulation_kite", "atmosphere", "segment_length_m", "sweep",
                   "reference_line", "table2")
#: ``tether:`` keys read by :func:`plan_flights`.
PLAN_KEYS = ("plan", "lines", "kites", "kite_model", "simulation_kite", "atmosphere", "segment_length_m", "sweep")
#: ``tether:`` keys of the line model, read by every entry point.
MODEL_KEYS = ("lines", "kites", "kite_model", "atmosphere", "segment_length_m")
#: ``tether:`` keys an entry point may also read (each rule passes the ones it uses).
OPTIONAL_KEYS = ("simulation_kite", "reference_line", "sweep", "table2", "plan", "observed")


@dataclass(frozen=True)
class TetherParams:
    """Parameters of the tether stage, from (part of) the ``tether:`` config section.

    Built by :meth:`from_config` with the same loaders as before
    (:mod:`kitegully.tether.config`), so the numbers are those of the config; every key is
    described in ``config/schema/stages/tether.schema.yaml``.

    Attributes
    ----------
    materials : dict of str to LineMaterial
        ``lines``: diameter, linear mass, breaking load and drag coefficient per line
        (mm → m, g/m → kg/m, daN → N). [P] Feurer et al. 2018 Table 1.
    kites : dict of str to Kite
        ``kites`` under the configured pull-angle reading ``kite_model``.
    kites_by_reading : dict of KiteModel to dict of str to Kite
        The same kites under each reading (the Table 2 check compares both).
    atmosphere : Atmosphere
        ``atmosphere``: air density and gravity. [P]
    segment_length_m : float
        ``segment_length_m``: length of the line's elements (m). [P]
    simulation_kite, reference_line : str or None
        The survey kite and the reference line (Fig. 5, dashed); ``None`` when not passed.
    sweep : mapping or None
        ``sweep``: winds (m/s), line lengths (m) and the line length of the shapes.
    sweep_lengths_m : ndarray or None
        The sweep's line lengths, 0 to ``sweep.max_line_length_m`` by ``line_length_step_m``.
    table2 : mapping or None
        ``table2``: the paper's Table 2 heights and the tolerance of the check. [P]
    plan : mapping or None
        ``plan``: flying heights, trigger, walking speed, overlap and GSD targets.
    planning_camera : PlanningCamera or None
        ``plan.camera``: the survey camera's sensor and lens.
    observed : mapping or None
        ``observed``: log source, settle time and flights with their line schedules.
    schedules : list of LineSchedule or None
        One line schedule per ``observed.flights`` entry (same order).
    synthetic_flights : list of SyntheticFlight or None
        The synthetic flights (``observed.source: synthetic`` only).
    log_settings : SyntheticLogSettings or None
        Geometry and noise of the synthetic logs (``observed.source: synthetic`` only).
    """

    materials: dict[str, LineMaterial]
    kites: dict[str, Kite]
    kites_by_reading: dict[KiteModel, dict[str, Kite]]
    atmosphere: Atmosphere
    segment_length_m: float
    simulation_kite: str | None = None
    reference_line: str | None = None
    sweep: Mapping[str, Any] | None = None
    sweep_lengths_m: np.ndarray | None = None
    table2: Mapping[str, Any] | None = None
    plan: Mapping[str, Any] | None = None
    planning_camera: PlanningCamera | None = None
    observed: Mapping[str, Any] | None = None
    schedules: list[LineSchedule] | None = None
    synthetic_flights: list[SyntheticFlight] | None = None
    log_settings: SyntheticLogSettings | None = None

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any], where: str = "tether") -> "TetherParams":
        """Build and check the parameters from the ``tether:`` keys a rule passes.

        Parameters
        ----------
        cfg : mapping
            The keys in :data:`MODEL_KEYS` and any of :data:`OPTIONAL_KEYS`.
        where : str
            Key path for messages.

        Raises
        ------
        InputError
            Naming the first missing or unknown key.
        """
        config_section(cfg, where, MODEL_KEYS, optional=OPTIONAL_KEYS)
        kites = kites_from_config(cfg)
        sim_kite = cfg.get("simulation_kite")
        if sim_kite is not None and sim_kite not in kites:
            raise InputError(f"{where}.simulation_kite: unknown kite '{sim_kite}' (defined: {', '.join(kites)})")
        sweep = cfg.get("sweep")
        plan = cfg.get("plan")
        obs = cfg.get("observed")
        schedules = flights = settings = None
        if obs is not None:
            schedules = [schedule_from_config(f, obs["settle_s"]) for f in obs["flights"]]
            if obs.get("source") == "synthetic":
                flights, settings = synthetic_flights_from_config(cfg)
        return cls(
            materials=materials_from_config(cfg),
            kites=kites,
            kites_by_reading={r: kites_from_config(cfg, r.value) for r in KiteModel},
            atmosphere=atmosphere_from_config(cfg),
            segment_length_m=cfg["segment_length_m"],
            simulation_kite=sim_kite,
            reference_line=cfg.get("reference_line"),
            sweep=sweep,
            sweep_lengths_m=None if sweep is None else sweep_lengths(cfg),
            table2=cfg.get("table2"),
            plan=plan,
            planning_camera=None if plan is None else planning_camera_from_config(plan["camera"]),
            observed=obs,
            schedules=schedules,
            synthetic_flights=flights,
            log_settings=settings,
        )


@dataclass
class TetherSimulation:
    """Products of :func:`simulate_tether`.

    Attributes
    ----------
    table : DataFrame
        Flight angle per material, wind and line length (:func:`flight_angle_table`).
    solutions : dict
        Line solutions at ``sweep.shape_line_length_m`` per material other than the reference line.
    reference : list
        The reference line's solutions (Fig. 5, dashed).
    comparison : DataFrame
        Table 2 comparison under both pull-angle readings, with ``within_tolerance``.
    """

    table: pd.DataFrame
    solutions: dict[str, Any]
    reference: Any
    comparison: pd.DataFrame


def _log_sweep(table: pd.DataFrame) -> None:
    for (material, wind), s in table[table["line_length_m"] > 0].groupby(["material", "wind_m_s"]):
        flying = s[s["flies"]]
        log.info(
            "%-10s %4.1f m/s: angle %.1f° at %g m -> %.1f° at %g m; %s",
            material, wind,
            flying["flight_angle_deg"].iloc[0] if len(flying) else np.nan, s["line_length_m"].min(),
            flying["flight_angle_deg"].iloc[-1] if len(flying) else np.nan,
            flying["line_length_m"].max() if len(flying) else np.nan,
            "line touches the ground beyond that" if (s["status"] != "flying").any() else "whole line airborne",
        )


def simulate_tether(params: TetherParams) -> TetherSimulation:
    """Flight angles over the sweep, line shapes and the Table 2 check (rule ``tether_simulation``).

    Parameters
    ----------
    params : TetherParams
        Built from the ``tether:`` keys in :data:`SIMULATION_KEYS`.

    Returns
    -------
    TetherSimulation

    Notes
    -----
    One catenary solve per material, wind and line length of the sweep (see
    :func:`kitegully.tether.line.solve_line`).
    """
    p = params
    materials = p.materials
    kite = p.kites[p.simulation_kite]
    atm = p.atmosphere
    ds = p.segment_length_m
    winds = p.sweep["winds_m_s"]
    log.info("kite %s, pull-angle reading %s, winds %s m/s", kite.name, kite.model.value, winds)
    table = flight_angle_table(materials, kite, winds, p.sweep_lengths_m, atm, ds)
    _log_sweep(table)

    shape_length = p.sweep["shape_line_length_m"]
    solutions = {
        name: solve_line(m, kite, winds, shape_length, atm, ds)
        for name, m in materials.items()
        if name != p.reference_line
    }
    reference = solve_line(materials[p.reference_line], kite, winds, shape_length, atm, ds)

    t2 = p.table2
    all_kites = {
        f"{reading.value} [{'I-A' if reading is KiteModel.BRIDLE_TENSION else 'I-B'}]":
            p.kites_by_reading[reading][p.simulation_kite]
        for reading in KiteModel
    }
    comparison = table2_comparison(
        materials[t2["material"]], all_kites, t2["winds_m_s"], t2["line_lengths_m"], t2["flying_heights_m"], atm, ds
    )
    comparison["within_tolerance"] = comparison["difference_pct"].abs() <= t2["tolerance_pct"]
    for reading, s in comparison.groupby("reading"):
        log.info(
            "Table 2 under %s: %d of %d heights within %g%% (differences %.1f%% to %.1f%%)",
            reading, int(s["within_tolerance"].sum()), len(s), t2["tolerance_pct"],
            s["difference_pct"].min(), s["difference_pct"].max(),
        )
    return TetherSimulation(table, solutions, reference, comparison)


def plan_flights(params: TetherParams) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The flight plan per flying height and the line lengths needed per material (rule ``tether_plan``).

    Parameters
    ----------
    params : TetherParams
        Built from the ``tether:`` keys in :data:`PLAN_KEYS`.

    Returns
    -------
    plan : DataFrame
        :func:`kitegully.tether.planning.plan_flight` for ``plan.flying_heights_m``.
    lengths : DataFrame
        :func:`line_lengths_for_heights` for the plan's heights, the sweep's winds and every material.
    """
    p = params
    plan_cfg = p.plan
    plan = plan_flight(
        p.planning_camera,
        flying_heights_m=plan_cfg["flying_heights_m"],
        worst_flight_angle_deg=plan_cfg["worst_flight_angle_deg"],
        trigger_interval_s=plan_cfg["trigger_interval_s"],
        walking_speed_m_s=plan_cfg["walking_speed_m_s"],
        stereo_min_overlap=plan_cfg["stereo_min_overlap"],
        max_flying_height_m=plan_cfg["max_flying_height_m"],
        target_gsd_m=plan_cfg["target_gsd_m"],
    )
    for row in plan.itertuples():
        log.info(
            "H %.0f m: line %.0f m, GSD %.3f m, footprint %.0f x %.0f m, overlap %.2f, B/H %.2f, dz %.3f m",
            row.flying_height_m, row.line_length_m, row.gsd_m, row.footprint_across_m, row.footprint_along_m,
            row.forward_overlap, row.base_height_ratio, row.precision_z_m,
        )
    lengths = line_lengths_for_heights(
        dict(p.materials),
        p.kites[p.simulation_kite],
        p.sweep["winds_m_s"],
        plan["flying_height_m"].tolist(),
        p.atmosphere,
        plan_cfg["model_max_line_length_m"],
        p.segment_length_m,
    )
    for row in lengths[~lengths["reachable"]].itertuples():
        log.warning("%s at %g m/s cannot reach %g m within %g m of line", row.material, row.wind_m_s, row.flying_height_m,
                    plan_cfg["model_max_line_length_m"])
    return plan, lengths


def synthetic_gps_logs(params: TetherParams, seed: int) -> list[tuple[str, pd.DataFrame, pd.DataFrame]]:
    """Camera and operator GPS logs of the synthetic flights of ``observed.synthetic`` (rule ``tether_synthetic_logs``).

    Parameters
    ----------
    params : TetherParams
        Built from the ``tether:`` line-model keys and ``observed`` (source ``synthetic``).
    seed : int
        The run's seed (one stream per flight, ``rng_for(seed, "tether", "gps", name)``).

    Returns
    -------
    list of (flight name, camera log, operator log)
    """
    if params.synthetic_flights is None:
        raise InputError("tether.observed: synthetic GPS logs need observed.source 'synthetic'")
    flights, settings = params.synthetic_flights, params.log_settings
    atm = params.atmosphere
    logs = []
    for flight in flights:
        rng = rng_for(seed, "tether", "gps", flight.name)
        camera, operator = simulate_flight_logs(flight, settings, atm, rng)
        log.info("%s: %d operator fixes, %d camera fixes (kite %s, %s, %.1f m/s)", flight.name, len(operator), len(camera),
                 flight.kite.name, flight.material.name, flight.mean_wind_m_s)
        logs.append((flight.name, camera, operator))
    return logs


@dataclass
class ObservedAngles:
    """Products of :func:`observed_flight_angles`."""

    fixes: pd.DataFrame
    summary: pd.DataFrame
    simulated: pd.DataFrame | None


def observed_flight_angles(
    params: TetherParams, camera_logs: list[str], operator_logs: list[str], crs: str
) -> ObservedAngles:
    """Effective flight angles from paired GPS logs, and the model curves for the flights' winds (rule ``tether_observed_angles``).

    Parameters
    ----------
    params : TetherParams
        Built from the ``tether:`` line-model keys, ``observed``, ``simulation_kite`` and ``sweep``.
    camera_logs, operator_logs : lists of paths
        GPX logs, one pair per flight of ``observed.flights`` (same order).
    crs : str
        Site CRS (m) the fixes are projected to.

    Returns
    -------
    ObservedAngles
        Paired fixes (``time`` as ISO text), their summary per flight, and the model's flight
        angles for the flights' winds and materials with the survey kite (``None`` without winds).
    """
    p = params
    obs = p.observed
    frames = []
    for flight, schedule, cam_path, op_path in zip(obs["flights"], p.schedules, camera_logs, operator_logs):
        angles = flight_angles(read_track(cam_path, crs), read_track(op_path, crs), schedule)
        angles.insert(0, "kite", flight["kite"])
        angles.insert(0, "flight", flight["name"])
        frames.append(angles)
        log.info("%s: %d paired fixes, angle %.1f-%.1f°", flight["name"], len(angles), angles["flight_angle_deg"].min(),
                 angles["flight_angle_deg"].max())
    fixes = pd.concat(frames, ignore_index=True)
    fixes["time"] = fixes["time"].dt.strftime("%Y-%m-%dT%H:%M:%SZ")
    summary = summarise_flight_angles(fixes)
    # Model curves for the flights' winds and line material, with the survey kite.
    winds = sorted({f["wind_m_s"] for f in obs["flights"] if "wind_m_s" in f})
    simulated = None
    if winds:
        material_names = {f["material"] for f in obs["flights"]}
        materials = {k: v for k, v in p.materials.items() if k in material_names}
        simulated = flight_angle_table(
            materials, p.kites[p.simulation_kite], winds, p.sweep_lengths_m, p.atmosphere, p.segment_length_m,
        )
    return ObservedAngles(fixes, summary, simulated)
