"""Close-range photogrammetry of eroded patches (Mayr et al. 2016, paper 001): stage closerange.

Pipeline side (photos and the sphere survey only); the photographs themselves are simulated
in :mod:`kitegully.twin.polewalk` (twin side, may use truth to build the scene), driven by
:func:`photograph_scene`.

Modules: ``spheres`` (automatic sub-pixel measurement of the white GCP spheres in the
photos, ellipse fit with the exact ellipse-centre → sphere-centre correction), ``model``
(oriented photos of the SfM model, sphere triangulation, pairing with the survey and the
similarity), ``markers`` (the spheres found in the oriented photos and the model georeferenced
on them), ``photos`` (the photographs read), ``dense`` (pairwise semi-global matching around
the ring), ``gridding`` (25 % trimmed-mean DEM and mean-colour orthophoto, cropped by the ring
of camera positions, outliers and small holes), ``foldrule`` and ``rule_photos`` (the rule's
legs measured in the photos, else in the orthophoto + DEM), ``tables`` (Table 1 and the OBIA
accuracy) and ``stage`` (entry points).
"""

import lazy_loader

__getattr__, __dir__, __all__ = lazy_loader.attach(
    __name__,
    submod_attrs={
        "stage": ["CloseRangeParams", "photograph_scene", "photogrammetric_orthophoto"],
        "tables": ["closerange_tables", "CloseRangeTables", "failed_scene_record", "scene_succeeded"],
    },
)
