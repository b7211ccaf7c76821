"""Gully mapping after Feurer et al. (2018, Fig. 3).

``depth`` (a-d: smoothed DEM minus DEM), ``patches`` (e-f: threshold, label, volume
filter), ``network`` (g-j: heads, steepest-descent tracing, Strahler order, lines),
``mapping`` (k-m: buffer ∩ patches, polygons), ``pipeline`` (the whole chain),
``sensitivity`` (σ × depth threshold), ``validation`` (the network scoring protocol,
:func:`~kitegully.gully.validation.score_network`, and the area scores against truth),
``plots`` (section view, validation map).
"""
