"""Close-range stereo photogrammetry of soil surfaces (Moritani et al. 2010, paper 003).

Library core: the paper's two-camera rig (:mod:`.rig`), the 3-D control field and its stations
(:mod:`.control_field`), inner orientation on it (:mod:`.calibration`) from targets measured in
rendered photographs (:mod:`.calibration_targets`), relative orientation and epipolar
rectification (:mod:`.rectify`), coarse-to-fine epipolar matching, triangulation and gridding (:mod:`.matching`), the printed
marks and tie points measured in the photographs (:mod:`.measure`), the paper's accuracy
measures (:mod:`.metrics`) and a direct projection renderer of textured height fields
(:mod:`.synth`).

The workflow stage (:mod:`.stage`; rules ``workflow/rules/stereo.smk``, site
``config/sites/stereo_lab.yaml``) runs the paper's calibration test, dry box, rain and wind
runs. Its entry points :func:`calibrate_rig`, :func:`measure_dry_box`, :func:`measure_rain`,
:func:`measure_wind` and their :class:`StereoParams` are imported lazily from here. Its parts:
the parameters (:mod:`.params`), the twin's laboratory (:mod:`.lab`), the processing of one
pair from observed data (:mod:`.processing`), the evaluation against the twin
(:mod:`.evaluation`) and the rain runs' process models (:mod:`.erosion`).
"""

import lazy_loader

__getattr__, __dir__, __all__ = lazy_loader.attach(
    __name__,
    submod_attrs={
        "stage": ["calibrate_rig", "measure_dry_box", "measure_rain", "measure_wind"],
        "params": ["StereoParams"],
    },
)
