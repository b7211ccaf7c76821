"""Object-based bare-soil (eroded area) classification after Mayr et al. (2016).

Modules, one job each:

``indices``      ExG on chromatic coordinates, NDVI, the Gaussian blur of ExG.
``slope``        Wood (1996) quadratic-surface slope in a square window.
``features``     z-normalisation of the segmentation features.
``seeds``        seed cells at minima of local feature variance (band-width smoothing).
``srg``          seeded region growing (Adams & Bischof 1994), compiled priority queue.
``threshold``    histogram-valley threshold with a bimodality check, Otsu alongside.
``classify``     segment means, grass/eroded labels, minimum-area filter, polygons.
``accuracy``     confusion matrix C[mapped, reference], user's/producer's/overall accuracy,
                 area errors.
``scene``        the whole chain for one orthophoto + DEM.
``kite``         the chain in tiles for a site-wide orthophoto + DSM.
``products``     one function per rule: classified scene, scene evaluation and figure,
                 summary over scenes, kite-scale map figure and accuracy.
"""
