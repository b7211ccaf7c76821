"""Kite line (tether) model, flight-angle analysis and flight planning (Feurer et al. 2018).

Modules: ``line`` (quasi-static line shape and kite position), ``planning`` (camera,
GSD, footprints, overlap, stereo precision), ``gps`` (flight angles from paired GPS logs,
synthetic logs), ``config`` (building the model objects from a site config), ``plots``,
``stage`` (the entry points, one per rule: ``simulate_tether``, ``plan_flights``,
``synthetic_gps_logs``, ``observed_flight_angles``; exported here lazily).
"""

import lazy_loader

__getattr__, __dir__, __all__ = lazy_loader.attach(
    __name__,
    submod_attrs={
        "stage": [
            "simulate_tether", "plan_flights", "synthetic_gps_logs", "observed_flight_angles",
            "TetherParams",
        ],
    },
)
