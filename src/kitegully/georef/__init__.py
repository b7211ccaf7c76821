"""Ground control: GCP files, triangulation, similarity transforms, GCP bundle adjustment, QA.

Modules: ``gcp_io`` (ODM ``gcp_list.txt`` and CSV parsing, reprojection with pyproj),
``geometry`` (camera projection, rotations, multi-view triangulation), ``similarity``
(Umeyama/Horn 7-parameter fits, tape-distance scale), ``bundle`` (our sparse
least-squares bundle adjustment with GCP terms; COLMAP's has none), ``model`` (moving
data between pycolmap models and arrays) and ``pipeline`` (QA flags, leave-one-out, the
whole georeferencing run).
"""
