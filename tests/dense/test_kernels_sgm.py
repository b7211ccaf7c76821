"""The compiled SGM cost / winner kernels equal the former numpy implementation bit for bit."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from kitegully.dense.kernels import _sgm_direction
from kitegully.dense.matching import MatchParams, _sgm_winner, _sgm_winner_reference
from kitegully.seeds import rng_for


def _score(shape, seed_item):
    rng = rng_for(21, "dense", seed_item)
    s = rng.uniform(-1.0, 1.0, shape).astype(np.float32)
    s[rng.random(shape) < 0.1] = np.nan
    # flat cost runs make ties (argmin takes the first) and zero parabola denominators
    s[:, :3, :3] = 0.25
    return s


def _naive_direction(cost, dr, dc, p1, p2):
    """Plain-Python SGM along one direction (the textbook recursion), float32."""
    H, W, K = cost.shape
    L = np.zeros_like(cost)
    rows = range(H) if dr >= 0 else range(H - 1, -1, -1)
    cols = range(W) if dc >= 0 else range(W - 1, -1, -1)
    for r in rows:
        for c in cols:
            pr, pc = r - dr, c - dc
            if not (0 <= pr < H and 0 <= pc < W):
                L[r, c] = cost[r, c]
                continue
            prev = L[pr, pc]
            m = prev.min()
            best = prev.copy()
            best[1:] = np.minimum(best[1:], prev[:-1] + p1)
            best[:-1] = np.minimum(best[:-1], prev[1:] + p1)
            best = np.minimum(best, m + p2)
            L[r, c] = cost[r, c] + best - m
    return L


def test_sgm_direction_is_the_sgm_recursion():
    cost = np.random.default_rng(4).random((5, 6, 4)).astype(np.float32)
    p1, p2 = np.float32(0.05), np.float32(0.3)
    for dr, dc in [(0, 1), (-1, 0), (1, 1), (-1, 1)]:
        total = np.zeros_like(cost)
        _sgm_direction(cost, dr, dc, p1, p2, total)
        assert np.allclose(total, _naive_direction(cost, dr, dc, p1, p2), atol=1e-6)


@pytest.mark.parametrize("K", [1, 2, 3, 7, 24])
def test_winner_equals_reference(K):
    score = _score((K, 23, 31), f"winner{K}")
    p = MatchParams()
    d_new, off_new = _sgm_winner(score, K, p)
    d_old, off_old = _sgm_winner_reference(score, K, p)
    assert np.array_equal(d_new, d_old)
    assert np.array_equal(off_new.astype(np.float64), np.asarray(off_old, np.float64))
    if K >= 3:
        assert np.abs(off_new).max() > 0.0  # the parabola is exercised


CHILD = r"""
import sys, numba, numpy as np
numba.set_num_threads(int(sys.argv[1]))
from kitegully.dense.matching import MatchParams, _sgm_winner
s = np.random.default_rng(5).uniform(-1, 1, (9, 40, 37)).astype(np.float32)
d, off = _sgm_winner(s, 9, MatchParams())
sys.stdout.write(str(hash(d.tobytes() + off.tobytes())))
"""


def test_winner_same_with_one_and_two_threads():
    import numba
    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("numba has a single thread here")
    out = [subprocess.run([sys.executable, "-c", CHILD, str(n)], capture_output=True, text=True, check=True,
                          env={**__import__("os").environ, "PYTHONHASHSEED": "0"}).stdout for n in (1, 2)]
    assert out[0] == out[1] and out[0]
