"""Structure from motion with pycolmap: image preparation, features, matching, mapping.

Modules: ``images`` (reading with EXIF orientation, downscaling, the pixel-frame maps
shared with the GCP code), ``reconstruct`` (pycolmap feature extraction, matching and
incremental mapping with one shared self-calibrated camera) and ``summary`` (model
statistics written to ``summary.json``).
"""
