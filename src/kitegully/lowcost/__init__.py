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

import lazy_loader

__getattr__, __dir__, __all__ = lazy_loader.attach(
    __name__,
    submod_attrs={
        "stage": ["measure_spectral_response", "survey_lowcost", "SurveyParams"],
        "bare_soil": ["map_bare_soil", "BareSoilParams"],
        "rtk": ["adjust_rtk_bundle"],
        "evaluation": ["evaluate_lowcost"],
        "twin_site": ["make_lowcost_twin"],
    },
)
