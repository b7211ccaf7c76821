"""Gully mapping after Feurer et al. (2018, Fig. 3).

``depth`` (a-d: smoothed DEM minus DEM), ``patches`` (e-f: threshold, label, volume
filter), ``network`` (g-j: heads, steepest-descent tracing, Strahler order, lines),
``mapping`` (k-m: buffer ∩ patches, polygons), ``pipeline`` (the whole chain),
``sensitivity`` (σ × depth threshold), ``validation`` (the network scoring protocol,
:func:`~kitegully.gully.validation.score_network`, and the area scores against truth),
``plots`` (section view, validation map), ``products`` (the map's files on disk).

Entry points (docs/architecture.md), exported here lazily: :func:`map_gullies` with
:class:`GullyParams` (``pipeline``), :func:`score_network` with :class:`ValidationParams`
and :func:`score_gully_areas` (``validation``), :func:`gully_sensitivity` (``sensitivity``).
"""

from importlib import import_module

_EXPORTS = {"GullyParams": "pipeline", "map_gullies": "pipeline", "gully_summary": "pipeline", "map_raster": "pipeline",
            "tracing_surface": "pipeline",
            "ValidationParams": "validation", "score_network": "validation", "score_gully_areas": "validation",
            "check_reference": "validation", "catchment_outline": "validation",
            "gully_sensitivity": "sensitivity", "write_map_products": "products", "score_networks": "validation"}
__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(import_module(f"{__name__}.{_EXPORTS[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
