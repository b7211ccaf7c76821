"""The tether stage's products, one function per rule (Feurer et al. 2018 sect. 2.2-2.3).

:func:`simulate_tether` makes the flight angle table, the line shapes of Fig. 5 and the
Table 2 comparison (rule ``tether_simulation``); :func:`plan_flights` makes the flight
plan and the line lengths the model needs per material (rule ``tether_plan``). Both take
the keys of the ``tether:`` config section they read (see the rules' ``params``).
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from kitegully.tether.analysis import flight_angle_table, line_lengths_for_heights, table2_comparison
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
from kitegully.tether.line import KiteModel, solve_line
from kitegully.tether.planning import plan_flight
from kitegully.seeds import rng_for

log = logging.getLogger(__name__)

#: ``tether:`` keys read by :func:`simulate_tether`.
SIMULATION_KEYS = ("lines", "kites", "kite_model", "simulation_kite", "atmosphere", "segment_length_m", "sweep",
                   "reference_line", "table2")
#: ``tether:`` keys read by :func:`plan_flights`.
PLAN_KEYS = ("plan", "lines", "kites", "kite_model", "simulation_kite", "atmosphere", "segment_length_m", "sweep")


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


def simulate_tether(cfg: Mapping[str, Any]) -> TetherSimulation:
    """Flight angles over the sweep, line shapes and the Table 2 check (rule ``tether_simulation``).

    Parameters
    ----------
    cfg : mapping
        The ``tether:`` keys in :data:`SIMULATION_KEYS`.

    Returns
    -------
    TetherSimulation

    Notes
    -----
    One catenary solve per material, wind and line length of the sweep (see
    :func:`kitegully.tether.line.solve_line`).
    """
    materials = materials_from_config(cfg)
    kite = kites_from_config(cfg)[cfg["simulation_kite"]]
    atm = atmosphere_from_config(cfg)
    ds = cfg["segment_length_m"]
    winds = cfg["sweep"]["winds_m_s"]
    log.info("kite %s, pull-angle reading %s, winds %s m/s", kite.name, kite.model.value, winds)
    table = flight_angle_table(materials, kite, winds, sweep_lengths(cfg), atm, ds)
    _log_sweep(table)

    shape_length = cfg["sweep"]["shape_line_length_m"]
    solutions = {
        name: solve_line(m, kite, winds, shape_length, atm, ds)
        for name, m in materials.items()
        if name != cfg["reference_line"]
    }
    reference = solve_line(materials[cfg["reference_line"]], kite, winds, shape_length, atm, ds)

    t2 = cfg["table2"]
    all_kites = {
        f"{reading.value} [{'I-A' if reading is KiteModel.BRIDLE_TENSION else 'I-B'}]":
            kites_from_config(cfg, reading.value)[cfg["simulation_kite"]]
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


def plan_flights(cfg: Mapping[str, Any]) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The flight plan per flying height and the line lengths needed per material (rule ``tether_plan``).

    Parameters
    ----------
    cfg : mapping
        The ``tether:`` keys in :data:`PLAN_KEYS`.

    Returns
    -------
    plan : DataFrame
        :func:`kitegully.tether.planning.plan_flight` for ``plan.flying_heights_m``.
    lengths : DataFrame
        :func:`line_lengths_for_heights` for the plan's heights, the sweep's winds and every material.
    """
    plan_cfg = cfg["plan"]
    plan = plan_flight(
        planning_camera_from_config(plan_cfg["camera"]),
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
        dict(materials_from_config(cfg)),
        kites_from_config(cfg)[cfg["simulation_kite"]],
        cfg["sweep"]["winds_m_s"],
        plan["flying_height_m"].tolist(),
        atmosphere_from_config(cfg),
        plan_cfg["model_max_line_length_m"],
        cfg["segment_length_m"],
    )
    for row in lengths[~lengths["reachable"]].itertuples():
        log.warning("%s at %g m/s cannot reach %g m within %g m of line", row.material, row.wind_m_s, row.flying_height_m,
                    plan_cfg["model_max_line_length_m"])
    return plan, lengths


def synthetic_gps_logs(cfg: Mapping[str, Any], seed: int) -> list[tuple[str, pd.DataFrame, pd.DataFrame]]:
    """Camera and operator GPS logs of the synthetic flights of ``observed.synthetic`` (rule ``tether_synthetic_logs``).

    Parameters
    ----------
    cfg : mapping
        The ``tether:`` line-model keys and ``observed``.
    seed : int
        The run's seed (one stream per flight, ``rng_for(seed, "tether", "gps", name)``).

    Returns
    -------
    list of (flight name, camera log, operator log)
    """
    flights, settings = synthetic_flights_from_config(cfg)
    atm = atmosphere_from_config(cfg)
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
    cfg: Mapping[str, Any], camera_logs: list[str], operator_logs: list[str], crs: str
) -> ObservedAngles:
    """Effective flight angles from paired GPS logs, and the model curves for the flights' winds (rule ``tether_observed_angles``).

    Parameters
    ----------
    cfg : mapping
        The ``tether:`` line-model keys, ``observed``, ``simulation_kite`` and ``sweep``.
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
    obs = cfg["observed"]
    frames = []
    for flight, cam_path, op_path in zip(obs["flights"], camera_logs, operator_logs):
        angles = flight_angles(read_track(cam_path, crs), read_track(op_path, crs),
                               schedule_from_config(flight, obs["settle_s"]))
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
        materials = {k: v for k, v in materials_from_config(cfg).items() if k in material_names}
        simulated = flight_angle_table(
            materials, kites_from_config(cfg)[cfg["simulation_kite"]], winds, sweep_lengths(cfg),
            atmosphere_from_config(cfg), cfg["segment_length_m"],
        )
    return ObservedAngles(fixes, summary, simulated)
