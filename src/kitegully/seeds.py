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


def epoch_rng(seed: int, epoch: int, stage: str, item: str) -> np.random.Generator:
    """Generator of a per-survey-epoch stream (issue 17).

    Epoch 1 keeps the stream it had before surveys had epochs,
    ``rng_for(seed, "<stage>.<item>")`` (= ``default_rng([seed, crc32("<stage>.<item>")])``),
    so its numbers are unchanged; a later epoch ``n`` draws from
    ``rng_for(seed, stage, "epoch<n>", item)``, independent of epoch 1.

    Parameters
    ----------
    seed : int
        The master seed.
    epoch : int
        Survey epoch, from 1.
    stage : str
        Stage name.
    item : str
        Item of the stage.

    Returns
    -------
    numpy.random.Generator
        The epoch's stream.
    """
    if int(epoch) == 1:
        return rng_for(seed, f"{stage}.{item}")
    return rng_for(seed, stage, f"epoch{int(epoch)}", item)


def epoch_seed(seed: int, epoch: int, stage: str, item: str) -> int:
    """Integer seed of a per-epoch stream for code that takes an int (a 32-bit value).

    Epoch 1 keeps ``crc32("<stage>.<item>") ^ seed`` (its numbers unchanged); a later epoch
    draws the int from :func:`epoch_rng`.

    Parameters
    ----------
    seed : int
        The master seed.
    epoch : int
        Survey epoch, from 1.
    stage : str
        Stage name.
    item : str
        Item of the stage.

    Returns
    -------
    int
        The stream's integer seed.
    """

    if int(epoch) == 1:
        return int(zlib.crc32(f"{stage}.{item}".encode("utf-8")) ^ int(seed))
    return int(epoch_rng(seed, epoch, stage, item).integers(0, 2**32 - 1))
