"""The renderer's texture pyramid built in one buffer equals the level-by-level pyramid."""

from __future__ import annotations

import numpy as np
import pytest

from kitegully.twin.render import _mip_flat, _mip_levels, make_scene


@pytest.mark.parametrize("shape, chunk", [((4, 67, 91), 1 << 22), ((4, 67, 91), 200), ((3, 130, 33), 40), ((1, 16, 16), 7)])
def test_flat_pyramid_equals_levels(shape, chunk):
    tex = np.random.default_rng(3).integers(0, 256, shape, dtype=np.uint8)
    levels = _mip_levels(tex)
    flat, offsets, shapes = _mip_flat(tex, chunk_cells=chunk)      # small chunks: many row blocks per level
    assert np.array_equal(flat, np.concatenate([lv.ravel() for lv in levels]))
    assert offsets.tolist() == np.cumsum([0] + [lv.size for lv in levels[:-1]]).tolist()
    assert shapes.tolist() == [list(lv.shape[:2]) for lv in levels]


def test_scene_holds_the_same_pyramid():
    tex = np.random.default_rng(4).integers(0, 256, (4, 80, 120), dtype=np.uint8)
    dsm = np.zeros((8, 12), np.float32)
    scene = make_scene(dsm, (0.0, 8.0), 1.0, tex, (0.0, 8.0), 0.1)
    assert np.array_equal(scene.tex, np.concatenate([lv.ravel() for lv in _mip_levels(tex)]))
    assert scene.tex_shapes[0].tolist() == [80, 120] and scene.nbands == 4
