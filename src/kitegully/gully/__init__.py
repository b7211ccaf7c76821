"""Gully mapping after Feurer et al. (2018, Fig. 3).

``depth`` (a-d: smoothed DEM minus DEM), ``patches`` (e-f: threshold, label, volume
filter), ``network`` (g-j: heads, steepest-descent tracing, Strahler order, lines),
``mapping`` (k-m: buffer ∩ patches, polygons), ``params`` (the method parameters),
``surface`` (the surfaces traced on: holes filled, crowns, object removal), ``pipeline`` (the whole chain),
``sensitivity`` (σ × depth threshold), ``validation`` (the network scoring protocol,
:func:`~kitegully.gully.validation.score_network`, and the area scores against truth),
``plots`` (section view, validation map), ``products`` (the map's files on disk).

Entry points (docs/architecture.md), exported here lazily: :func:`map_gullies` with
:class:`GullyParams` (``params``), :func:`score_network` with :class:`ValidationParams`
and :func:`score_gully_areas` (``validation``), :func:`gully_sensitivity` (``sensitivity``).
"""

import lazy_loader

__getattr__, __dir__, __all__ = lazy_loader.attach(
    __name__,
    submod_attrs={
        "params": ["GullyParams"],
        "pipeline": ["map_gullies", "gully_summary", "map_raster"],
        "surface": ["tracing_surface"],
        "validation": [
            "ValidationParams", "score_network", "score_gully_areas", "check_reference", "catchment_outline",
            "score_networks",
        ],
        "sensitivity": ["gully_sensitivity"],
        "products": ["write_map_products"],
    },
)
