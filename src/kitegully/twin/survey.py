"""What the field team brings home: RTK points, a surveyed gully network, digitised heads.

* GCPs and checkpoints carry RTK noise (normal, σ horizontal per axis and σ vertical).
* Checkpoints lie on open ground only (``open_classes`` everywhere within
  ``clearance_m``), a share clustered around the reservoir like the lake survey of
  Feurer et al. (2018, Fig. 1c) and the rest spread over the site.
* The field network is the truth split into sections at confluences and where the width
  changes by more than ``section_width_ratio``, displaced by a smooth mapping error.
* Gully heads are digitised with a normal error of ``heads_sigma_m`` per axis.
"""

from __future__ import annotations

import logging

import geopandas as gpd
import numpy as np
import pandas as pd
from shapely.geometry import LineString, Point

from kitegully.io.raster import GridSpec
from kitegully.seeds import rng_for
from kitegully.twin.gullies import Gully
from kitegully.twin.landcover import CODE
from kitegully.twin.noise import fbm_points
from kitegully.twin.targets import eligible, sample_bilinear

log = logging.getLogger(__name__)


def rtk_observe(df: pd.DataFrame, id_col: str, sigma_h: float, sigma_v: float, rng: np.random.Generator) -> pd.DataFrame:
    """Add RTK noise to true points (columns id, x, y, z)."""
    n = len(df)
    return pd.DataFrame({
        id_col: df[id_col].to_numpy(),
        "x": df["x"].to_numpy() + rng.normal(0.0, sigma_h, n),
        "y": df["y"].to_numpy() + rng.normal(0.0, sigma_h, n),
        "z": df["z"].to_numpy() + rng.normal(0.0, sigma_v, n),
    })


def sample_checkpoints(ccfg: dict, lc: np.ndarray, dtm: np.ndarray, grid: GridSpec, centre: tuple[float, float], seed: int) -> pd.DataFrame:
    """True checkpoint positions (``id, x, y, z`` on the DTM), clustered + spread.

    Rejection sampling in batches; O(batches·stencil). Logs a warning if fewer points
    than asked fit the open ground.
    """
    rng = rng_for(seed, "twin", "checkpoints")
    n_total = ccfg["count"]
    n_cluster = int(round(ccfg["cluster_share"] * n_total))
    xmin, ymin, xmax, ymax = grid.bounds
    m = ccfg["edge_margin_m"]
    out = []
    for part, n_want in (("cluster", n_cluster), ("spread", n_total - n_cluster)):
        got_x, got_y = np.zeros(0), np.zeros(0)
        for _ in range(50):
            if len(got_x) >= n_want:
                break
            nb = 4 * n_want + 100
            if part == "cluster":
                r = ccfg["cluster_radius_m"] * np.sqrt(rng.uniform(size=nb))
                th = rng.uniform(0, 2 * np.pi, nb)
                x, y = centre[0] + r * np.cos(th), centre[1] + r * np.sin(th)
            else:
                x, y = rng.uniform(xmin, xmax, nb), rng.uniform(ymin, ymax, nb)
            inside = (x > xmin + m) & (x < xmax - m) & (y > ymin + m) & (y < ymax - m)
            x, y = x[inside], y[inside]
            ok = eligible(lc, grid, x, y, ccfg["open_classes"], ccfg["clearance_m"])
            got_x = np.concatenate([got_x, x[ok]])
            got_y = np.concatenate([got_y, y[ok]])
        if len(got_x) < n_want:
            log.warning("only %d of %d %s checkpoints fit on open ground", len(got_x), n_want, part)
        out.append((got_x[:n_want], got_y[:n_want]))
    x = np.concatenate([o[0] for o in out])
    y = np.concatenate([o[1] for o in out])
    z = sample_bilinear(dtm, grid, x, y)
    return pd.DataFrame({"id": [f"CP{i + 1:04d}" for i in range(len(x))], "x": x, "y": y, "z": z})


def lake_centre(lc: np.ndarray, grid: GridSpec, fallback: tuple[float, float]) -> tuple[float, float]:
    """Centroid of the water cells (the reservoir), or ``fallback`` if there is none."""
    r, c = np.nonzero(lc[::4, ::4] == CODE["water"])
    if len(r) == 0:
        return fallback
    xs, ys = grid.cell_centres()
    return float(xs[::4][c].mean()), float(ys[::4][r].mean())


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """(start, stop) of runs of True."""
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.nonzero(d == 1)[0], np.nonzero(d == -1)[0]))


def _under_water(x: np.ndarray, y: np.ndarray, water: np.ndarray | None, grid: GridSpec | None) -> np.ndarray:
    """True for points on a water cell of ``water`` (False everywhere without a mask)."""
    if water is None or grid is None:
        return np.zeros(len(x), dtype=bool)
    r, c = grid.rowcol(np.asarray(x), np.asarray(y))
    r = np.round(r).astype(int)
    c = np.round(c).astype(int)
    inside = (r >= 0) & (c >= 0) & (r < water.shape[0]) & (c < water.shape[1])
    out = np.zeros(len(x), dtype=bool)
    out[inside] = water[r[inside], c[inside]]
    return out


def field_network(gullies: list[Gully], scfg: dict, min_depth: float, crs: str, seed: int,
                  water: np.ndarray | None = None, grid: GridSpec | None = None) -> gpd.GeoDataFrame:
    """The network as surveyed: sections split at confluences and size changes, displaced.

    The mapping error is a smooth random displacement field of amplitude
    ``mapping_error_m`` and wavelength ``mapping_wavelength_m`` (GPS positions of
    upstream/middle/downstream points, delineation on imagery). Reaches under open water
    (``water``, a boolean raster on ``grid``: the reservoir) cannot be walked or seen and
    are left out.
    """
    rng = rng_for(seed, "twin", "field_network")
    sx, sy = rng.integers(0, 2**31 - 1, 2)
    wl = np.array([scfg["mapping_wavelength_m"]])
    amp = np.array([scfg["mapping_error_m"]])
    confl: dict[int, list[int]] = {}
    for g in gullies:
        if g.joins >= 0 and g.join_index >= 0:
            confl.setdefault(g.joins, []).append(g.join_index)
    rows = []
    for g in gullies:
        cuts = set(confl.get(g.gully_id, []))
        for a, b in _runs((g.depth >= min_depth) & ~_under_water(g.x, g.y, water, grid)):
            start = a
            w0 = g.width[a]
            s = g.s
            for i in range(a + 1, b):
                long_enough = s[i] - s[start] >= scfg["min_section_length_m"]
                ratio = max(g.width[i], w0) / max(min(g.width[i], w0), 1e-6)
                if long_enough and (i in cuts or ratio > scfg["section_width_ratio"] or i == b - 1):
                    rows.append((g, start, i))
                    start, w0 = i, g.width[i]
            if start < b - 1 and s[b - 1] - s[start] > 0:
                rows.append((g, start, b - 1))
    recs = []
    for k, (g, i0, i1) in enumerate(rows):
        x, y = g.x[i0:i1 + 1], g.y[i0:i1 + 1]
        if len(x) < 2:
            continue
        dx = fbm_points(x, y, int(sx), wl, amp)
        dy = fbm_points(x, y, int(sy), wl, amp)
        w_true = float(np.mean(g.width[i0:i1 + 1]))
        w_est = w_true * float(np.exp(rng.normal(0.0, scfg["width_estimate_sigma"])))
        step = scfg["width_estimate_step_m"]
        recs.append({"section_id": k + 1, "gully_no": g.gully_id, "width_m": max(step, round(w_est / step) * step),
                     "geometry": LineString(np.column_stack([x + dx, y + dy]))})
    return gpd.GeoDataFrame(recs, geometry="geometry", crs=crs)


def digitised_heads(gullies: list[Gully], sigma: float, crs: str, seed: int) -> gpd.GeoDataFrame:
    """Gully heads as digitised on a shaded DEM: truth heads plus normal error (m)."""
    rng = rng_for(seed, "twin", "digitised_heads")
    heads = [(g.x[0], g.y[0]) for g in gullies if g.kind != "wadi"]
    if not heads:
        return gpd.GeoDataFrame({"head_id": []}, geometry=[], crs=crs)
    h = np.asarray(heads)
    order = np.argsort(h[:, 0] + 1e-3 * h[:, 1])
    h = h[order] + rng.normal(0.0, sigma, h.shape)
    return gpd.GeoDataFrame({"head_id": np.arange(1, len(h) + 1)}, geometry=[Point(p) for p in h], crs=crs)
