"""Second epoch: the same site after a season of erosion.

Changes from epoch 1 (every amount drawn per gully from the config ranges, keyed by the
gully id so they are reproducible):

* headcut retreat: gullies with a headcut grow upslope by ``headcut_retreat_m`` along the
  direction of their first segment;
* widening and deepening: width × (1 + ``widening_fraction``), depth + ``deepening_m``;
* sheet erosion: bare-soil classes lose ``sheet_erosion_m`` × (1 + variability·noise).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from kitegully.seeds import rng_for
from kitegully.twin.gullies import Gully
from kitegully.twin.noise import fbm_grid

if TYPE_CHECKING:
    import pandas as pd

    from kitegully.io.raster import GridSpec


def retreat_heads(gullies: list[Gully], ecfg: dict, seed: int) -> dict[int, float]:
    """Extend headcut gullies upslope in place; returns the retreat (m) per gully id.

    The extension gets vertices no farther apart than the gully's own first segment (the
    tracing step), so the retreated head keeps the form it had at epoch 1: depth and width
    are set per vertex and interpolated along segments, and one vertex at the new head
    would make the head a wedge as long as the retreat instead of a headwall.

    Parameters
    ----------
    gullies : list of Gully
        The epoch-1 network; headcut gullies (not the wadi) are extended, and receiving gullies get
        their ``join_index`` shifted.
    ecfg : mapping
        ``twin.epoch2``; reads ``headcut_retreat_m`` (range, m).
    seed : int
        Master seed.

    Returns
    -------
    dict of int to float
        Retreat (m) per gully id of the gullies that were extended.
    """
    out: dict[int, float] = {}
    shift: dict[int, int] = {}
    lo, hi = ecfg["headcut_retreat_m"]
    for g in gullies:
        if g.kind == "wadi" or not g.headcut or len(g.x) < 2:
            continue
        r = float(rng_for(seed, "twin", "epoch2", "retreat", str(g.gully_id)).uniform(lo, hi))
        tx, ty = g.x[1] - g.x[0], g.y[1] - g.y[0]
        n = np.hypot(tx, ty)
        if n == 0 or r <= 0:
            continue
        m = int(np.ceil(r / n - 1e-9))
        back = r * np.arange(m, 0, -1) / m  # distances upslope of the old head, the new head first
        g.x = np.concatenate([g.x[0] - back * tx / n, g.x])
        g.y = np.concatenate([g.y[0] - back * ty / n, g.y])
        out[g.gully_id] = r
        shift[g.gully_id] = m
    # receiving gullies that gained vertices at the head shift their indices
    for g in gullies:
        if g.joins in shift and g.join_index >= 0:
            g.join_index += shift[g.joins]
    return out


def widening(gullies: list[Gully], ecfg: dict, seed: int) -> dict[int, tuple[float, float]]:
    """Width factor and depth increment per gully id (wadi included).

    Parameters
    ----------
    gullies : list of Gully
        The network.
    ecfg : mapping
        ``twin.epoch2``; reads ``widening_fraction`` (range) and ``deepening_m`` (m).
    seed : int
        Master seed.

    Returns
    -------
    dict of int to tuple of float
        ``(1 + widening fraction, deepening_m)`` per gully id.
    """
    lo, hi = ecfg["widening_fraction"]
    return {
        g.gully_id: (1.0 + float(rng_for(seed, "twin", "epoch2", "widen", str(g.gully_id)).uniform(lo, hi)), ecfg["deepening_m"])
        for g in gullies
    }


def sheet_erosion(xs: np.ndarray, ys: np.ndarray, ecfg: dict, seed: int) -> np.ndarray:
    """Lowering (m, ≥ 0) of bare soil on a grid: mean ``sheet_erosion_m``, patchy.

    Parameters
    ----------
    xs, ys : ndarray
        Column and row coordinates of the grid (m); the result has shape ``(len(ys), len(xs))``.
    ecfg : mapping
        ``twin.epoch2``; reads ``sheet_erosion_m`` (m), ``sheet_erosion_wavelength_m`` (m) and
        ``sheet_erosion_variability``.
    seed : int
        Seed of the noise field.

    Returns
    -------
    ndarray (len(ys), len(xs)) float64
        Lowering (m, ≥ 0).
    """
    n = fbm_grid(xs, ys, seed, np.array([ecfg["sheet_erosion_wavelength_m"]]), np.array([1.0]))
    return ecfg["sheet_erosion_m"] * np.clip(1.0 + ecfg["sheet_erosion_variability"] * n, 0.0, None)


def disturb_targets(targets: pd.DataFrame, ecfg: dict, seed: int, lc: np.ndarray, grid: GridSpec,
                    open_classes: list[str]) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Epoch-2 GCP targets: a few lost, a few moved, as happens between two field campaigns.

    ``targets_lost`` targets (drawn at random) are gone: not painted, not surveyed, absent
    from the epoch-2 tables. ``targets_moved`` others were knocked over and laid out again
    ``target_move_m`` (range) away in a random direction on open ground (land cover in
    ``open_classes``; a target with no open spot within 24 tries stays); the surveyor measures
    them where they lie, so the survey is consistent with the painted target. Keys absent =
    none lost or moved. Returns (targets, log table with gcp_id, fate, dx_m, dy_m).

    Parameters
    ----------
    targets : pandas.DataFrame
        Epoch-1 targets (``gcp_id, x, y, ...``).
    ecfg : Mapping
        ``twin.epoch2``.
    seed : int
    lc : numpy.ndarray
        Epoch-2 land-cover codes on ``grid``.
    grid : GridSpec
    open_classes : list of str
        Land-cover names a target may lie on (``twin.targets.classes``).
    """
    import pandas as pd

    from kitegully.twin.landcover import CODE

    n_lost = int(ecfg.get("targets_lost", 0) or 0)
    n_moved = int(ecfg.get("targets_moved", 0) or 0)
    lo, hi = ecfg.get("target_move_m", [2.0, 5.0])
    if n_lost + n_moved > len(targets) - 4:
        from kitegully import InputError
        raise InputError(f"twin.epoch2: targets_lost + targets_moved ({n_lost + n_moved}) must leave at least 4 of the "
                         f"{len(targets)} targets in place")
    rng = rng_for(seed, "twin", "epoch2", "targets")
    order = rng.permutation(len(targets))
    lost, moved = order[:n_lost], order[n_lost:n_lost + n_moved]
    ok_codes = np.array([CODE[c] for c in open_classes])
    out = targets.copy().reset_index(drop=True)
    fate = []
    for i in moved:
        x0, y0 = float(out.at[i, "x"]), float(out.at[i, "y"])
        for _ in range(24):
            d, a = rng.uniform(lo, hi), rng.uniform(0.0, 2.0 * np.pi)
            x, y = x0 + d * np.sin(a), y0 + d * np.cos(a)
            r, c = (int(v) for v in np.round(grid.rowcol(x, y)))
            if 0 <= r < lc.shape[0] and 0 <= c < lc.shape[1] and np.isin(lc[r, c], ok_codes):
                out.at[i, "x"], out.at[i, "y"] = x, y
                fate.append({"gcp_id": out.at[i, "gcp_id"], "fate": "moved", "dx_m": x - x0, "dy_m": y - y0})
                break
    fate += [{"gcp_id": out.at[i, "gcp_id"], "fate": "lost", "dx_m": np.nan, "dy_m": np.nan} for i in lost]
    out = out.drop(index=lost).reset_index(drop=True)
    return out, pd.DataFrame(fate, columns=["gcp_id", "fate", "dx_m", "dy_m"])


def texture_config(texture: dict, ecfg: dict | None) -> dict:
    """``twin.texture`` for epoch 2: the second survey day's sun (``twin.epoch2.illumination``,
    merged over ``texture.illumination``; the renderer bakes the sun into the texture)."""
    ill = (ecfg or {}).get("illumination")
    if not ill:
        return texture
    return {**texture, "illumination": {**texture["illumination"], **ill}}
