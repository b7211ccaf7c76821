"""Structure from motion with pycolmap: image preparation, features, matching, mapping.

Entry point (docs/architecture.md): :func:`reconstruct_model` with its parameters
:class:`SfmParams` (both in ``stage``), and :func:`load_image_infos` that later stages use
to read what it wrote. Imported lazily, so ``import kitegully.sfm.images`` stays light.

Modules: ``stage`` (the stage: parameters, files in and out), ``images`` (reading with
EXIF orientation, downscaling, the pixel-frame maps shared with the GCP code), ``priors``
(camera GPS log → position priors), ``reconstruct`` (pycolmap feature extraction,
matching and incremental mapping with one shared self-calibrated camera) and ``summary``
(model statistics written to ``summary.json``).
"""

import lazy_loader

__getattr__, __dir__, __all__ = lazy_loader.attach(
    __name__,
    submod_attrs={
        "stage": ["reconstruct_model", "SfmParams", "SfmMatching", "load_image_infos"],
    },
)
