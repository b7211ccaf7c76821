"""Close-range photogrammetry of eroded patches (Mayr et al. 2016, paper 001): library parts.

Pipeline side (observed inputs only); the photographs themselves are simulated in
:mod:`kitegully.twin.polewalk` (twin side, may use truth to build the scene).

Modules: ``spheres`` (automatic sub-pixel measurement of the white GCP spheres in the
photos, ellipse fit with the exact ellipse-centre → sphere-centre correction) and
``gridding`` (25 % trimmed-mean DEM and mean-colour orthophoto from dense points, cropped
by the ring of camera positions).  No stage, rule or config keys yet (issue 20).
"""
