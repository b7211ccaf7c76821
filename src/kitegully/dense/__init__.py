"""Dense multi-view matching in object space (after MicMac's Malt) to a DSM, true orthophoto and relief shading.

Modules: ``views`` (oriented images, pycolmap reader, image pyramids), ``kernels``
(compiled resampling, multi-image correlation, SGM, occlusion, openness), ``matching``
(one tile, coarse to fine), ``surface`` (tiled site DSM), ``ortho`` (true orthophoto),
``shading`` (hillshade, openness).
"""
