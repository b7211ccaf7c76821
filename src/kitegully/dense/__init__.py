"""Dense multi-view matching in object space (after MicMac's Malt) to a DSM, true orthophoto and relief shading.

Entry point (docs/architecture.md): :func:`match_dense_surface` with its parameters
:class:`DenseParams` (both in ``stage``). Imported lazily, so importing a kernel module
stays light.

Modules: ``stage`` (the stage: parameters, files in and out), ``views`` (oriented images,
pycolmap reader, image pyramids), ``kernels`` (compiled resampling, multi-image
correlation, SGM, occlusion, openness), ``matching`` (one tile, coarse to fine),
``surface`` (tiled site DSM), ``tiles`` (the DSM as Snakemake tile jobs of a large site, issue 21), ``datum`` (vertical datum check at the GCP targets), ``ortho`` (true
orthophoto), ``shading`` (hillshade, openness).
"""

from importlib import import_module

_EXPORTS = {"match_dense_surface": "stage", "DenseParams": "stage", "OrthoParams": "stage", "ShadingParams": "stage",
            "MatchParams": "matching"}
__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(import_module(f"{__name__}.{_EXPORTS[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
