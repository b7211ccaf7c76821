"""Reproducible random streams: every stage derives its generator from the config seed."""

from __future__ import annotations

import zlib

import numpy as np


def rng_for(seed: int, *names: str) -> np.random.Generator:
    """A NumPy generator for the master ``seed`` and a path of names (stage, item, ...).

    The same seed and names always give the same stream; different names give
    independent streams (``numpy.random.SeedSequence`` with CRC32 of each name).
    """
    return np.random.default_rng([int(seed), *(zlib.crc32(n.encode("utf-8")) for n in names)])
