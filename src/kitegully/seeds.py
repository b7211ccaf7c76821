"""Reproducible random streams: every stage derives its generator from the config seed."""

from __future__ import annotations

import zlib

import numpy as np


def rng_for(seed: int, *names: str | int) -> np.random.Generator:
    """A NumPy generator for the master ``seed`` and a path of names (stage, item, ...).

    The same seed and names always give the same stream; different names give
    independent streams (``numpy.random.SeedSequence`` with CRC32 of each name).
    A non-negative integer in the path (e.g. an image index) enters the seed sequence
    as is, so ``rng_for(seed, i)`` is ``default_rng([seed, i])`` and ``rng_for(seed)``
    is ``default_rng(seed)``.
    """
    return np.random.default_rng([int(seed), *(int(n) if isinstance(n, (int, np.integer)) else zlib.crc32(n.encode("utf-8")) for n in names)])
