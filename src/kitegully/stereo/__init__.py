"""Close-range stereo photogrammetry of soil surfaces (Moritani et al. 2010, paper 003).

Library core only (issue 19): the paper's two-camera rig (:mod:`.rig`), inner orientation
on a 3-D control field (:mod:`.calibration`), relative orientation and epipolar
rectification (:mod:`.rectify`), coarse-to-fine epipolar matching, triangulation and
gridding (:mod:`.matching`), the paper's accuracy measures (:mod:`.metrics`) and a direct
projection renderer of textured height fields for tests and benchmarks (:mod:`.synth`).
The workflow stage (:mod:`.stage`; rules ``workflow/rules/stereo.smk``, site
``config/sites/stereo_lab.yaml``) runs the paper's calibration test, dry box, rain and wind runs.
"""
