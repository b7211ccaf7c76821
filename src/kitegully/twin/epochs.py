"""Second epoch: the same site after a season of erosion.

Changes from epoch 1 (every amount drawn per gully from the config ranges, keyed by the
gully id so they are reproducible):

* headcut retreat: gullies with a headcut grow upslope by ``headcut_retreat_m`` along the
  direction of their first segment;
* widening and deepening: width × (1 + ``widening_fraction``), depth + ``deepening_m``;
* sheet erosion: bare-soil classes lose ``sheet_erosion_m`` × (1 + variability·noise).
"""

from __future__ import annotations

import numpy as np

from kitegully.seeds import rng_for
from kitegully.twin.gullies import Gully
from kitegully.twin.noise import fbm_grid


def retreat_heads(gullies: list[Gully], ecfg: dict, seed: int) -> dict[int, float]:
    """Extend headcut gullies upslope in place; returns the retreat (m) per gully id."""
    out: dict[int, float] = {}
    lo, hi = ecfg["headcut_retreat_m"]
    for g in gullies:
        if g.kind == "wadi" or not g.headcut or len(g.x) < 2:
            continue
        r = float(rng_for(seed, "twin", "epoch2", "retreat", str(g.gully_id)).uniform(lo, hi))
        tx, ty = g.x[1] - g.x[0], g.y[1] - g.y[0]
        n = np.hypot(tx, ty)
        if n == 0 or r <= 0:
            continue
        g.x = np.concatenate([[g.x[0] - r * tx / n], g.x])
        g.y = np.concatenate([[g.y[0] - r * ty / n], g.y])
        out[g.gully_id] = r
    # receiving gullies that gained a vertex at the head shift their indices
    shift = {gid: 1 for gid in out}
    for g in gullies:
        if g.joins in shift and g.join_index >= 0:
            g.join_index += shift[g.joins]
    return out


def widening(gullies: list[Gully], ecfg: dict, seed: int) -> dict[int, tuple[float, float]]:
    """Width factor and depth increment per gully id (wadi included)."""
    lo, hi = ecfg["widening_fraction"]
    return {
        g.gully_id: (1.0 + float(rng_for(seed, "twin", "epoch2", "widen", str(g.gully_id)).uniform(lo, hi)), ecfg["deepening_m"])
        for g in gullies
    }


def sheet_erosion(xs: np.ndarray, ys: np.ndarray, ecfg: dict, seed: int) -> np.ndarray:
    """Lowering (m, ≥ 0) of bare soil on a grid: mean ``sheet_erosion_m``, patchy."""
    n = fbm_grid(xs, ys, seed, np.array([ecfg["sheet_erosion_wavelength_m"]]), np.array([1.0]))
    return ecfg["sheet_erosion_m"] * np.clip(1.0 + ecfg["sheet_erosion_variability"] * n, 0.0, None)
