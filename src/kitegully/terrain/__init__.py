"""Terrain analysis on gridded DEMs.

Modules, one job each:

``smoothing``
    Gaussian smoothing by FFT convolution with zero padding and normalised
    convolution for nodata (Feurer et al. 2018, Fig. 3 b-c).
``holes``
    Interpolation of interior nodata holes (Laplace equation).
``fill``
    Priority-flood depression filling with an epsilon gradient (Barnes et al. 2014),
    compiled with numba, O(n log n).
``flats``
    Drainage over flats of a filled DEM (Barnes et al. 2014 flat resolution): every
    cell drains, paths converge instead of running in parallel.
``flow``
    D8 flow directions and steepest-descent tracing on a depression-free DEM.
``least_cost``
    Drainage directions of an unfilled DEM by least-cost search (depressions breached
    along their lowest route, after GRASS ``r.watershed``), O(n log n).
``shading``
    The Lambertian hillshade the project's maps are drawn over.
"""

from kitegully.terrain.fill import priority_flood_fill
from kitegully.terrain.flats import flow_directions
from kitegully.terrain.flow import D8_OFFSETS, d8_directions, trace_paths
from kitegully.terrain.holes import interior_holes, interpolate_holes
from kitegully.terrain.least_cost import least_cost_directions
from kitegully.terrain.smoothing import gaussian_kernel_1d, gaussian_smooth_fft

__all__ = [
    "D8_OFFSETS",
    "d8_directions",
    "flow_directions",
    "gaussian_kernel_1d",
    "gaussian_smooth_fft",
    "interior_holes",
    "interpolate_holes",
    "least_cost_directions",
    "priority_flood_fill",
    "trace_paths",
]
