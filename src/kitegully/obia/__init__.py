"""Object-based bare-soil (eroded area) classification after Mayr et al. (2016).

Modules, one job each:

``indices``      ExG on chromatic coordinates, NDVI, the Gaussian blur of ExG.
``slope``        Wood (1996) quadratic-surface slope in a square window.
``features``     z-normalisation of the segmentation features.
``seeds``        seed cells at minima of local feature variance (band-width smoothing).
``srg``          seeded region growing (Adams & Bischof 1994), compiled priority queue.
``threshold``    histogram-valley threshold with a bimodality check, Otsu alongside; the valley bounding the lowest ExG mode (bare soil) for histograms with more modes.
``classify``     segment means, grass/eroded labels, minimum-area filter, polygons.
``accuracy``     confusion matrix C[mapped, reference], user's/producer's/overall accuracy,
                 area errors.
``scene``        the whole chain for one orthophoto + DEM.
``kite``         the chain in tiles for a site-wide orthophoto + DSM.
``stage``        the entry points, one per rule (exported here lazily): classified scene,
                 scene evaluation and figure, summary over scenes, kite-scale map figure
                 and accuracy; the parameters are ``scene.ObiaParams``.
"""

from importlib import import_module

_EXPORTS = {"ObiaParams": "scene", "classify_scene_products": "stage", "evaluate_scene": "stage",
            "scene_figure": "stage", "summarise_scenes": "stage", "summary_figure": "stage",
            "bare_soil_map": "kite", "kite_map_figure": "stage", "kite_accuracy": "stage"}
__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(import_module(f"{__name__}.{_EXPORTS[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
