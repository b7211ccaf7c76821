"""Close-range photogrammetry of eroded patches (Mayr et al. 2016, paper 001): stage closerange.

Pipeline side (photos and the sphere survey only); the photographs themselves are simulated
in :mod:`kitegully.twin.polewalk` (twin side, may use truth to build the scene), driven by
:func:`photograph_scene`.

Modules: ``spheres`` (automatic sub-pixel measurement of the white GCP spheres in the
photos, ellipse fit with the exact ellipse-centre → sphere-centre correction), ``model``
(oriented photos of the SfM model, sphere triangulation, pairing with the survey and the
similarity), ``dense`` (pairwise semi-global matching around the ring), ``gridding`` (25 %
trimmed-mean DEM and mean-colour orthophoto, cropped by the ring of camera positions),
``foldrule`` (the rule's legs measured in the orthophoto + DEM) and ``stage`` (entry points).
"""

from importlib import import_module

_EXPORTS = {
    "CloseRangeParams": "stage", "photograph_scene": "stage", "photogrammetric_orthophoto": "stage",
    "closerange_tables": "stage", "CloseRangeTables": "stage",
    "failed_scene_record": "stage", "scene_succeeded": "stage",
}
__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(import_module(f"{__name__}.{_EXPORTS[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
