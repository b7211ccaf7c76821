"""The low-cost kite survey of Bryson et al. (2013): spectral response of consumer RGB and
NIR-converted cameras, taped scale + Horn's absolute orientation, NDVI, slope and aspect.

Implemented so far: :mod:`~kitegully.lowcost.spectral` (camera spectral response from a
simulated Macbeth-chart shot) and :mod:`~kitegully.lowcost.surface` (NDVI, slope and
aspect rasters). The tape scale and Horn's method live in
:mod:`kitegully.georef.similarity`. The twin at the paper's scale, the two rendered
flights, joint SfM and the orthomosaics are not implemented yet.
"""
