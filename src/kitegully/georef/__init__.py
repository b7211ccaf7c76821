"""Ground control: GCP files, triangulation, similarity transforms, GCP bundle adjustment, QA.

Entry point (docs/architecture.md): :func:`georeference` with its parameters
:class:`GeorefParams` (both in ``stage``); :func:`georeference_block` is the same on arrays.
Imported lazily, so ``import kitegully.georef.gcp_io`` stays light.

Modules: ``stage`` (the stage: parameters, files in and out), ``control`` (QA flags,
leave-one-out, the georeferencing of a block), ``gcp_io`` (ODM ``gcp_list.txt`` and CSV
parsing, reprojection with pyproj), ``geometry`` (camera projection, rotations,
multi-view triangulation), ``similarity`` (Umeyama/Horn 7-parameter fits, tape-distance
scale), ``bundle`` (our sparse least-squares bundle adjustment with GCP terms; COLMAP's
has none), ``model`` (moving data between pycolmap models and arrays), ``export``
(products) and ``evaluate`` (twin evaluation against the flight truth).
"""

import lazy_loader

__getattr__, __dir__, __all__ = lazy_loader.attach(
    __name__,
    submod_attrs={
        "stage": ["georeference", "GeorefParams", "GeorefQA"],
        "control": ["georeference_block", "GeorefResult"],
        "evaluate": ["evaluate_against_flight_truth"],
    },
)
