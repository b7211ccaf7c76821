"""Build tether-model objects from the ``tether`` section of a site configuration."""

from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from kitegully import InputError
from kitegully.tether.gps import LineSchedule, SyntheticFlight, SyntheticLogSettings
from kitegully.tether.line import Atmosphere, Kite, KiteModel, LineMaterial
from kitegully.tether.planning import PlanningCamera


def materials_from_config(cfg: Mapping[str, Any]) -> dict[str, LineMaterial]:
    """Line materials, converting mm → m, g/m → kg/m and daN → N."""
    out = {}
    for name, m in cfg["lines"].items():
        load = m.get("breaking_load_daN")
        out[name] = LineMaterial(
            name=name,
            diameter_m=m["diameter_mm"] * 1e-3,
            linear_mass_kg_m=m["linear_mass_g_m"] * 1e-3,
            breaking_load_n=None if load is None else load * 10.0,
            drag_coefficient=m["drag_coefficient"],
        )
    return out


def kites_from_config(cfg: Mapping[str, Any], model: str | None = None) -> dict[str, Kite]:
    """Kites under the configured reading of the pull angle (or ``model`` if given)."""
    reading = KiteModel(model or cfg["kite_model"])
    return {
        name: Kite(
            name=name,
            area_m2=k["area_m2"],
            drag_coefficient=k["drag_coefficient"],
            pull_angle_deg=k["pull_angle_deg"],
            wing_mass_kg=k["wing_mass_kg"],
            payload_mass_kg=k["payload_mass_kg"],
            model=reading,
        )
        for name, k in cfg["kites"].items()
    }


def atmosphere_from_config(cfg: Mapping[str, Any]) -> Atmosphere:
    """The atmosphere of a ``tether`` config section.

    Parameters
    ----------
    cfg : mapping
        The ``tether`` section; reads ``atmosphere.air_density_kg_m3`` and ``atmosphere.gravity_m_s2``.

    Returns
    -------
    Atmosphere
    """
    a = cfg["atmosphere"]
    return Atmosphere(air_density_kg_m3=a["air_density_kg_m3"], gravity_m_s2=a["gravity_m_s2"])


def tether_from_config(cfg: Mapping[str, Any]) -> tuple[dict[str, LineMaterial], dict[str, Kite], Atmosphere]:
    """``(materials, kites, atmosphere)`` from a ``tether`` config section."""
    return materials_from_config(cfg), kites_from_config(cfg), atmosphere_from_config(cfg)


def planning_camera_from_config(cam: Mapping[str, Any]) -> PlanningCamera:
    """The planning camera from a ``tether.plan.camera`` config section."""
    return PlanningCamera(
        sensor_width_mm=cam["sensor_width_mm"],
        sensor_height_mm=cam["sensor_height_mm"],
        image_width_px=cam["image_width_px"],
        image_height_px=cam["image_height_px"],
        focal_length_mm=cam["focal_length_mm"],
        long_side_across_track=cam["long_side_across_track"],
    )


def sweep_lengths(cfg: Mapping[str, Any]) -> np.ndarray:
    """Line lengths of the sweep (m): from 0 in steps of ``sweep.line_length_step_m``.

    Parameters
    ----------
    cfg : mapping
        The ``tether`` section; reads ``sweep.max_line_length_m`` and ``sweep.line_length_step_m``.

    Returns
    -------
    ndarray
        Line lengths (m), ``max_line_length_m`` included when it is a whole number of steps.
    """
    s = cfg["sweep"]
    return np.arange(0.0, s["max_line_length_m"] + 0.5 * s["line_length_step_m"], s["line_length_step_m"])


def schedule_from_config(flight: Mapping[str, Any], settle_s: float) -> LineSchedule:
    """The line schedule of one observed flight.

    Parameters
    ----------
    flight : mapping
        One entry of ``observed.flights``; its ``line_schedule`` lists ``start_s`` and
        ``line_length_m`` of each step.
    settle_s : float
        Seconds after each change of length whose fixes are dropped.

    Returns
    -------
    LineSchedule
    """
    steps = flight["line_schedule"]
    return LineSchedule(
        start_s=tuple(float(s["start_s"]) for s in steps),
        lengths_m=tuple(float(s["line_length_m"]) for s in steps),
        settle_s=settle_s,
    )


def synthetic_flights_from_config(cfg: Mapping[str, Any]) -> tuple[list[SyntheticFlight], SyntheticLogSettings]:
    """The synthetic flights of ``tether.observed`` and the shared log geometry/noise."""
    obs = cfg["observed"]
    syn = obs["synthetic"]
    materials = materials_from_config(cfg)
    kites = kites_from_config(cfg)
    flights = [
        SyntheticFlight(
            name=f["name"],
            kite=kites[f["kite"]],
            material=materials[f["material"]],
            mean_wind_m_s=f["wind_m_s"],
            gust_sd_m_s=syn["gust_sd_m_s"],
            gust_time_constant_s=syn["gust_time_constant_s"],
            schedule=schedule_from_config(f, obs["settle_s"]),
            duration_s=int(f["duration_s"]),
            start_time=f["start_time"],
        )
        for f in obs["flights"]
    ]
    settings = SyntheticLogSettings(
        origin_x=syn["origin_x"],
        origin_y=syn["origin_y"],
        ground_z=syn["ground_z"],
        walk_azimuth_deg=syn["walk_azimuth_deg"],
        wind_to_azimuth_deg=syn["wind_to_azimuth_deg"],
        walking_speed_m_s=syn["walking_speed_m_s"],
        rig_drop_m=syn["rig_drop_m"],
        gps_horizontal_sd_m=syn["gps_horizontal_sd_m"],
        gps_vertical_sd_m=syn["gps_vertical_sd_m"],
        kite_response_s=syn.get("kite_response_s", 0.0),
        pendulum_rms_deg=syn.get("pendulum_rms_deg", 0.0),
        walking_speed_sd_m_s=syn.get("walking_speed_sd_m_s", 0.0),
    )
    return flights, settings


def check_tether_config(cfg: Mapping[str, Any], source: str = "tether") -> None:
    """Cross-reference checks the JSON schema cannot express.

    Raises
    ------
    InputError
        Naming the key whose value refers to something undefined or is missing for the
        chosen log source.
    """
    kites, lines = cfg["kites"], cfg["lines"]

    def need(value: str, pool: Mapping[str, Any], key: str, what: str) -> None:
        if value not in pool:
            raise InputError(f"{source}.{key}: unknown {what} '{value}' (defined: {', '.join(pool)})")

    need(cfg["simulation_kite"], kites, "simulation_kite", "kite")
    need(cfg["reference_line"], lines, "reference_line", "line")
    need(cfg["table2"]["material"], lines, "table2.material", "line")
    t2 = cfg["table2"]
    if len(t2["line_lengths_m"]) != len(t2["flying_heights_m"]):
        raise InputError(f"{source}.table2: line_lengths_m and flying_heights_m must have the same length")
    if cfg["sweep"]["shape_line_length_m"] > cfg["sweep"]["max_line_length_m"]:
        raise InputError(f"{source}.sweep.shape_line_length_m exceeds max_line_length_m")
    obs = cfg["observed"]
    if obs["source"] == "synthetic" and "synthetic" not in obs:
        raise InputError(f"{source}.observed.synthetic is required when observed.source is 'synthetic'")
    for i, flight in enumerate(obs["flights"]):
        key = f"observed.flights[{i}]"
        need(flight["kite"], kites, f"{key}.kite", "kite")
        need(flight["material"], lines, f"{key}.material", "line")
        starts = [s["start_s"] for s in flight["line_schedule"]]
        if starts != sorted(starts) or starts[0] != 0:
            raise InputError(f"{source}.{key}.line_schedule must start at 0 s and be in time order")
        wanted = ("wind_m_s", "duration_s", "start_time") if obs["source"] == "synthetic" else ("camera_log", "operator_log")
        for k in wanted:
            if k not in flight:
                raise InputError(f"{source}.{key}.{k} is required when observed.source is '{obs['source']}'")
