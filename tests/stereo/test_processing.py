"""The processing of a pair from observed data: tie points that lie on the surface."""

import numpy as np

from kitegully.stereo.processing import surface_consistent


def test_surface_consistent_drops_a_false_match_along_the_epipolar_line():
    rng = np.random.default_rng(0)
    uv = rng.uniform(0, 400, (500, 2))
    d = -150 + 0.05 * uv[:, 0] + np.where(uv[:, 1] > 200, 6.0, 0.0)  # a tilted surface with a 6 px step (a rim)
    d[7] = 55.0  # the right row, the wrong place: it fits the coplanarity condition
    keep = surface_consistent(uv, d, 10.0)
    assert not keep[7] and keep.sum() == 499
    assert surface_consistent(uv[:5], d[:5], 10.0).all()  # too few ties to judge: all kept
