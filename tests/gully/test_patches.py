"""depth_patches: the in-place renumbering (session 10) gives the former gather's labels."""

import numpy as np
import pytest
import scipy.ndimage as ndi

from kitegully.gully.patches import depth_patches


@pytest.mark.parametrize("connectivity", [4, 8])
def test_depth_patches_labels_equal_the_renumbered_components(connectivity):
    rng = np.random.default_rng(7)
    depth = ndi.gaussian_filter(rng.standard_normal((300, 260)), 3.0).astype(np.float32) * 4
    depth[100:120, 50:90] = np.nan
    labels, table = depth_patches(depth, 0.2, 0.25, 0.05, connectivity)
    # reference: the former code's full-grid gather new_id[labels]
    st = ndi.generate_binary_structure(2, 2 if connectivity == 8 else 1)
    with np.errstate(invalid="ignore"):
        raw, n = ndi.label(depth > 0.25, structure=st, output=np.int32)
    vol = ndi.sum_labels(np.nan_to_num(depth).astype(np.float64), raw, index=np.arange(1, n + 1)) * 0.04
    keep = np.concatenate([[False], vol >= 0.05])
    new_id = np.zeros(n + 1, np.int32)
    new_id[keep] = np.arange(1, keep.sum() + 1)
    want = new_id[raw]
    assert labels.dtype == np.int32
    assert np.array_equal(labels, want)
    assert 0 < table["kept"].sum() < len(table) == n  # some patches dropped, some kept
    assert np.array_equal(table["patch_id"].to_numpy(), new_id[1:])
