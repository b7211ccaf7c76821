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

import lazy_loader

__getattr__, __dir__, __all__ = lazy_loader.attach(
    __name__,
    submod_attrs={
        "stage": ["match_dense_surface", "DenseParams", "OrthoParams", "ShadingParams"],
        "matching": ["MatchParams"],
    },
)
