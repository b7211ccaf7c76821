"""Digital twin of a Kamech-like catchment (Feurer et al. 2018): a synthetic site with truth.

One concern per module: ``noise`` (hash-based fractal noise, tile-independent),
``terrain`` (valley, reservoir, micro-relief), ``gullies`` (network tracing and carving),
``landcover`` (plots, tracks, trees, buildings, shrubs, water), ``texture`` (RGB+NIR
reflectance), ``targets`` (GCP placement and painting), ``survey`` (RTK points, field
network, digitised heads), ``epochs`` (second-epoch erosion), ``site`` (configuration,
planning and the tiled generator) and ``figures`` (report figures). Imports are kept light
here on purpose; import the submodules you need.
"""
