"""The low-cost kite survey of Bryson et al. (2013): spectral response of consumer RGB and
NIR-converted cameras, taped scale + Horn's absolute orientation, NDVI, slope and aspect.

Entry points (imported lazily from here): :func:`measure_spectral_response` and
:func:`survey_lowcost` with :class:`SurveyParams` (``stage``), :func:`map_bare_soil` with
:class:`BareSoilParams` (``bare_soil``), :func:`adjust_rtk_bundle` (``rtk``, the RTK
comparison block) and :func:`evaluate_lowcost` (``evaluation``, against the twin's truth;
evaluation only). :func:`make_lowcost_twin` (``twin_site``) builds the twin.

Modules: :mod:`~kitegully.lowcost.spectral` (camera spectral response from a simulated
Macbeth-chart shot), :mod:`~kitegully.lowcost.surface` (NDVI, slope and aspect rasters),
:mod:`~kitegully.lowcost.twin_site` (the twin: shore strip, RGB and NIR flights, targets,
GPS, tape, tide), :mod:`~kitegully.lowcost.georef` (click triangulation, tape + Horn +
tide, waterline levelling), :mod:`~kitegully.lowcost.matches` (verified matches by sensor
pair) and :mod:`~kitegully.lowcost.products` (TIN DSM, views in the site CRS, white
balance). The tape scale and Horn's method live in :mod:`kitegully.georef.similarity`.
"""

from importlib import import_module

_EXPORTS = {
    "measure_spectral_response": "stage", "survey_lowcost": "stage", "SurveyParams": "stage",
    "map_bare_soil": "bare_soil", "BareSoilParams": "bare_soil", "adjust_rtk_bundle": "rtk",
    "evaluate_lowcost": "evaluation", "make_lowcost_twin": "twin_site",
}
__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(import_module(f"{__name__}.{_EXPORTS[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
