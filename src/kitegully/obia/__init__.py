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

import lazy_loader

__getattr__, __dir__, __all__ = lazy_loader.attach(
    __name__,
    submod_attrs={
        "scene": ["ObiaParams"],
        "stage": [
            "classify_scene_products", "evaluate_scene", "scene_figure", "summarise_scenes",
            "summary_figure", "kite_map_figure", "kite_accuracy",
        ],
        "kite": ["bare_soil_map"],
    },
)
