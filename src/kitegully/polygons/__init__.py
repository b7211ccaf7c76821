"""Gully polygons and morphometry from a DEM (Höfle et al. 2013; METHODS.md sect. 3).

Modules by phase of the method:

``dem_prep``
    Minimum-z resampling of the DSM/DTM to the stage's cell; empty cells filled by
    moving planes (best-fit plane through the k nearest valid cells within a radius).
``breaklines``
    Wood's bivariate quadratic in an n × n window by least-squares convolution kernels,
    curvature, threshold, skeleton: the convex upper gully edges.
``skeleton``
    One-cell-wide skeletons to polylines (graph walk) and longest paths.
``thalweg``
    Multiple-flow-direction specific catchment area, TCI = ln(a / tan β), thalweg lines.
``transects``
    Orthogonal dams along the thalweg, clipped between the nearest breakline crossings.
``conditioning``
    Barriers raised into the DEM, priority-flood fill, fill depth, threshold masks,
    closing, polygons.
``medial``
    Medial axes: thinning, longest path or pruned network, snakes, prolonged to the outline.
``profiles``
    Profiles draped on the DEM, their ground, and the depth reference surfaces.
``morphometry``
    Cross-sections every 10 m across the medial axes: width, depth, area and volume.
``manual``
    Simulated manual operators digitising the gullies on the shaded DEM (twins only).
``evaluation``
    Paper Table 1, polygon scores and morphometry errors against the twin's truth.
``plots``
    Figures like the paper's Figs 8-11.
``stage``
    :class:`PolygonParams` and :func:`measure_polygons`, the whole chain.

Entry points (docs/architecture.md): :func:`measure_polygons` with its parameters
:class:`PolygonParams` (``stage``); the twin evaluation :func:`regenerate_table1` and
:func:`evaluate_against_truth` (``evaluation``). Imported lazily, so importing a phase
module stays light.
"""

import lazy_loader

__getattr__, __dir__, __all__ = lazy_loader.attach(
    __name__,
    submod_attrs={
        "stage": ["measure_polygons", "PolygonParams", "PolygonResult"],
        "evaluation": ["regenerate_table1", "evaluate_against_truth"],
    },
)
