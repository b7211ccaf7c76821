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

from importlib import import_module

_EXPORTS = {"reconstruct_model": "stage", "SfmParams": "stage", "SfmMatching": "stage", "load_image_infos": "stage"}
__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(import_module(f"{__name__}.{_EXPORTS[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
