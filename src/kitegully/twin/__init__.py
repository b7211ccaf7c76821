"""Digital twin of a Kamech-like catchment (Feurer et al. 2018): a synthetic site with truth.

One concern per module: ``noise`` (hash-based fractal noise, tile-independent),
``terrain`` (valley, reservoir, micro-relief), ``gullies`` (network tracing and carving),
``landcover`` (plots, tracks, trees, buildings, shrubs, water), ``texture`` (RGB+NIR
reflectance), ``targets`` (GCP placement and painting), ``survey`` (RTK points, field
network, digitised heads), ``epochs`` (second-epoch erosion), ``site`` (configuration,
planning and the tiled generator) and ``figures`` (report figures). The flight stage's
library is here too: ``flight`` (strips, kite and camera motion, GPS), ``render_flight``,
``flight_gcps`` and ``flight_stage`` (one function per flight rule).

Entry points of the twin stage (docs/architecture.md): :func:`build_site` (the plan),
:func:`generate_epoch` (truth and observed files of one epoch) and :func:`write_site_json`,
with their parameters :class:`TwinParams` (all in ``site``). They are imported lazily, so
importing a submodule stays light.
"""

from importlib import import_module

_EXPORTS = {"TwinParams": "site", "build_site": "site", "generate_epoch": "site", "write_site_json": "site",
            "PLAN_KEYS": "site", "EPOCH_KEYS": "site", "EPOCH2_KEYS": "site",
            "fly_kite": "flight_stage", "photograph_flight": "flight_stage", "flight_map": "flight_stage",
            "sample_images": "flight_stage"}
__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(import_module(f"{__name__}.{_EXPORTS[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
