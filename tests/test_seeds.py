"""kitegully.seeds.rng_for: named streams, and integer items that keep the streams the
code drew before issue 13 (``default_rng([seed, i])``, ``default_rng(seed)``)."""

from __future__ import annotations

import zlib

import numpy as np

from kitegully.seeds import rng_for


def test_named_streams_are_reproducible_and_independent():
    a = rng_for(7, "twin", "heads").random(8)
    assert np.array_equal(a, rng_for(7, "twin", "heads").random(8))
    assert not np.array_equal(a, rng_for(7, "twin", "fields").random(8))
    assert not np.array_equal(a, rng_for(8, "twin", "heads").random(8))
    assert np.array_equal(rng_for(7, "flight.gcps").random(4), np.random.default_rng([7, zlib.crc32(b"flight.gcps")]).random(4))


def test_integer_items_pass_through_unchanged():
    for seed in (0, 7, 2018, 2**40 + 3):
        assert np.array_equal(rng_for(seed).random(5), np.random.default_rng(seed).random(5))
        for i in (0, 1, 57):
            assert np.array_equal(rng_for(seed, i).random(5), np.random.default_rng([seed, i]).random(5))
            assert np.array_equal(rng_for(seed, np.int64(i)).random(5), np.random.default_rng([seed, i]).random(5))
    assert not np.array_equal(rng_for(7, 1).random(5), rng_for(7, "1").random(5))
