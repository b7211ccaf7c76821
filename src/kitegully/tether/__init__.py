"""Kite line (tether) model, flight-angle analysis and flight planning (Feurer et al. 2018).

Modules: ``line`` (quasi-static line shape and kite position), ``planning`` (camera,
GSD, footprints, overlap, stereo precision), ``gps`` (flight angles from paired GPS logs,
synthetic logs), ``config`` (building the model objects from a site config), ``plots``,
``stage`` (the entry points, one per rule: ``simulate_tether``, ``plan_flights``,
``synthetic_gps_logs``, ``observed_flight_angles``; exported here lazily).
"""

from importlib import import_module

_EXPORTS = {"simulate_tether": "stage", "plan_flights": "stage", "synthetic_gps_logs": "stage",
            "observed_flight_angles": "stage", "TetherParams": "stage"}
__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(import_module(f"{__name__}.{_EXPORTS[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
