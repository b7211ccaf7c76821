"""The low-cost kite survey of Bryson et al. (2013): spectral response of consumer RGB and
NIR-converted cameras, taped scale + Horn's absolute orientation, NDVI, slope and aspect.

Modules: :mod:`~kitegully.lowcost.spectral` (camera spectral response from a simulated
Macbeth-chart shot), :mod:`~kitegully.lowcost.surface` (NDVI, slope and aspect rasters),
:mod:`~kitegully.lowcost.twin_site` (the twin: shore strip, RGB and NIR flights, targets,
GPS, tape, tide), :mod:`~kitegully.lowcost.georef` (click triangulation, tape + Horn +
tide, waterline levelling) and :mod:`~kitegully.lowcost.stage` (the stage's entry points
``measure_spectral_response``, ``survey_lowcost``, ``evaluate_lowcost``). The tape scale
and Horn's method live in :mod:`kitegully.georef.similarity`.
"""
