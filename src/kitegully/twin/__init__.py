"""Digital twin of a Kamech-like catchment (Feurer et al. 2018): a synthetic site with truth.

One concern per module: ``noise`` (hash-based fractal noise, tile-independent),
``terrain`` (valley, reservoir, micro-relief), ``gullies`` (network tracing and carving),
``landcover`` (plots, tracks, trees, buildings, shrubs, water), ``texture`` (RGB+NIR
reflectance), ``targets`` (GCP placement and painting), ``survey`` (RTK points, field
network, digitised heads), ``epochs`` (second-epoch erosion), ``gully_truth`` (the true
gullies as vectors: centrelines, polygons, heads), ``site`` (configuration,
planning and the tiled generator) and ``figures`` (report figures). The flight stage's
library is here too: ``flight`` (strips, kite and camera motion, GPS), ``render_flight``,
``flight_gcps`` and ``flight_stage`` (one function per flight rule).

Entry points of the twin stage (docs/architecture.md): :func:`build_site` (the plan),
:func:`generate_epoch` (truth and observed files of one epoch) and :func:`write_site_json`,
with their parameters :class:`TwinParams` (all in ``site``). They are imported lazily, so
importing a submodule stays light.
"""

import lazy_loader

__getattr__, __dir__, __all__ = lazy_loader.attach(
    __name__,
    submod_attrs={
        "site": [
            "TwinParams", "build_site", "generate_epoch", "write_site_json", "PLAN_KEYS", "EPOCH_KEYS",
            "EPOCH2_KEYS",
        ],
        "flight_stage": ["fly_kite", "photograph_flight", "flight_map", "sample_images"],
    },
)
