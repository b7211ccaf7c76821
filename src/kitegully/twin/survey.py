"""What the field team brings home: RTK points, a surveyed gully network, digitised heads.

* GCPs and checkpoints carry RTK noise (normal, σ horizontal per axis and σ vertical).
* Checkpoints lie on open ground only (``open_classes`` everywhere within
  ``clearance_m``), a share clustered around the reservoir like the lake survey of
  Feurer et al. (2018, Fig. 1c) and the rest spread over the site.
* The field network is the truth split into sections at confluences and where the width
  changes by more than ``section_width_ratio``, displaced by a smooth mapping error.
* Gully heads are digitised as an operator sees them on the hillshade of the
  photogrammetric DSM: only where the incision is visible at the DSM's noise and
  resolution (:func:`digitised_heads` states the rule), marginal ones missed at a stated
  rate, a few false heads on tracks and furrows, and a normal error of ``heads_sigma_m``
  (the accuracy the operator claims) per axis.
"""

from __future__ import annotations

import logging

import geopandas as gpd
import numpy as np
import pandas as pd
from scipy.spatial import cKDTree
from shapely.geometry import LineString, Point

from kitegully.io.raster import GridSpec
from kitegully.seeds import rng_for
from kitegully.twin.gullies import Gully
from kitegully.twin.landcover import CODE
from kitegully.twin.noise import fbm_points
from kitegully.twin.targets import eligible, sample_bilinear

log = logging.getLogger(__name__)


def rtk_observe(df: pd.DataFrame, id_col: str, sigma_h: float, sigma_v: float, rng: np.random.Generator) -> pd.DataFrame:
    """Add RTK noise to true points (columns id, x, y, z).

    Parameters
    ----------
    df : DataFrame
        True points.
    id_col : str
        Name of the id column, copied as is.
    sigma_h : float
        Horizontal standard deviation per axis (m).
    sigma_v : float
        Vertical standard deviation (m).
    rng : numpy.random.Generator
        Random stream.

    Returns
    -------
    DataFrame
        Columns ``id_col, x, y, z``, one row per point, in the same order.
    """
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

    Parameters
    ----------
    ccfg : mapping
        ``twin.survey.checkpoints``; reads ``count``, ``cluster_share``, ``cluster_radius_m`` (m),
        ``edge_margin_m`` (m), ``open_classes`` and ``clearance_m`` (m).
    lc : ndarray
        Land-cover codes on ``grid``.
    dtm : ndarray
        Ground elevation (m) on ``grid``.
    grid : GridSpec
        The DEM grid.
    centre : tuple of float
        Centre ``(x, y)`` of the cluster (m).
    seed : int
        Master seed.

    Returns
    -------
    DataFrame
        ``id`` (``CP0001``, ...), ``x``, ``y``, ``z`` (m): the clustered points first.
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
    """Centroid of the water cells (the reservoir), or ``fallback`` if there is none.

    Parameters
    ----------
    lc : ndarray
        Land-cover codes on ``grid``; every 4th row and column is read.
    grid : GridSpec
        The grid of ``lc``.
    fallback : tuple of float
        ``(x, y)`` returned when there is no water (m).

    Returns
    -------
    tuple of float
        ``(x, y)`` of the centroid (m).
    """
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

    Parameters
    ----------
    gullies : list of Gully
        The true network.
    scfg : mapping
        ``twin.survey.field_network``; reads ``mapping_error_m`` (m), ``mapping_wavelength_m`` (m),
        ``min_section_length_m`` (m), ``section_width_ratio``, ``width_estimate_sigma`` and
        ``width_estimate_step_m`` (m).
    min_depth : float
        Least depth of a surveyed reach (m).
    crs : str
        Site CRS.
    seed : int
        Seed of the mapping error and the width estimates.
    water : ndarray of bool or None
        Open water on ``grid``; None leaves no reach out.
    grid : GridSpec or None
        The grid of ``water``.

    Returns
    -------
    GeoDataFrame
        One line per section: ``section_id``, ``gully_no``, ``width_m`` (estimated, rounded to
        ``width_estimate_step_m``).
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


# ------------------------------------------------------------------ digitised heads
#: Keys of ``twin.survey.heads_visibility`` (see :func:`digitised_heads`).
HEAD_VISIBILITY_KEYS = ("dsm_sigma_z_m", "dsm_resolution_m", "relief_k", "min_run_cells", "marginal_miss_rate",
                        "false_heads_per_km2", "false_head_classes", "false_head_clearance_m")


def shape_factor(shape: str, u_exponent: float) -> float:
    """Cross-section area / (depth · width) of the twin's profiles ``D·(1 − (d/h)^p)``: p/(p+1).

    V sections (p = 1) hold half the rectangle, U sections (p = ``u_exponent``) ``p/(p+1)``.
    """
    p = u_exponent if shape == "U" else 1.0
    return p / (p + 1.0)


def resolved_relief(depth: np.ndarray, width: np.ndarray, factor: float, resolution_m: float) -> np.ndarray:
    """Relief (m) of a channel cross-section as a DSM of horizontal resolution ``resolution_m`` shows it.

    Dense matching averages heights over its window (``resolution_m`` wide), so a channel
    narrower than the window keeps its cross-section area ``a = factor·depth·width`` but
    spreads it over the window: its apparent depth is ``a / resolution_m``; a wider channel
    keeps its depth. Hence ``min(depth, a / resolution_m)``: depth × width is what decides.

    Parameters
    ----------
    depth, width : ndarray
        Depth and width of the channel (m).
    factor : float
        Cross-section area / (depth · width), see :func:`shape_factor`.
    resolution_m : float
        Horizontal resolution of the DSM (m).

    Returns
    -------
    ndarray
        Resolved relief (m).
    """
    a = factor * np.asarray(depth, dtype=float) * np.asarray(width, dtype=float)
    return np.minimum(np.asarray(depth, dtype=float), a / resolution_m)


def visible_head_index(s: np.ndarray, relief: np.ndarray, threshold_m: float, min_run_m: float) -> int:
    """Index of the first vertex of the first run where ``relief ≥ threshold_m`` over ``≥ min_run_m``.

    Returns -1 when no run is long enough (the incision is never seen). ``s`` is the
    distance along the channel from the head (m), increasing.

    Parameters
    ----------
    s : ndarray
        Distance from the head at each vertex (m).
    relief : ndarray
        Resolved relief at each vertex (m).
    threshold_m : float
        Least visible relief (m).
    min_run_m : float
        Least length of a visible run (m).

    Returns
    -------
    int
        Vertex index, or -1.
    """
    vis = np.asarray(relief) >= threshold_m
    d = np.diff(np.concatenate([[0], vis.astype(np.int8), [0]]))
    for a, b in zip(np.nonzero(d == 1)[0], np.nonzero(d == -1)[0]):
        if s[b - 1] - s[a] >= min_run_m:
            return int(a)
    return -1


def digitised_heads(gullies: list[Gully], sigma: float, crs: str, seed: int, vis: dict, u_exponent: float,
                    landcover: np.ndarray | None = None, grid: GridSpec | None = None) -> gpd.GeoDataFrame:
    """Gully heads as an operator digitises them on the hillshade of the photogrammetric DSM.

    Visibility rule (``vis`` = ``twin.survey.heads_visibility``). The DSM has vertical
    noise ``σ_z`` (``dsm_sigma_z_m``) and horizontal resolution ``W`` (``dsm_resolution_m``,
    the dense-matching window). A channel reach shows in the hillshade when

    1. its resolved relief (:func:`resolved_relief`, ``min(D, a/W)`` with ``a`` the
       cross-section area, i.e. depth × width) is at least ``k·σ_z`` (``relief_k``, 3: a
       3σ step is exceeded by noise in 0.13 % of cells, and the hillshade contrast of a
       slope scales with sin(zenith) for signal and noise alike, so the SNR, not the sun
       elevation, decides to first order), and
    2. it does so over at least ``n`` resolution cells along the channel
       (``min_run_cells`` × ``W``; n = 3: a line, not a dot, and the chance that noise
       makes a 3σ step in 3 independent cells in a row is ~1e-9).

    The operator digitises the upstream end of the first visible run (a tapering head is
    placed downstream of the true head; a gully never visible is missed). Heads whose
    largest resolved relief over that run stays below ``2·k·σ_z`` are marginal and are
    missed with probability ``marginal_miss_rate``. Positions carry a normal error of
    ``sigma`` (the accuracy the operator claims) per axis. ``false_heads_per_km2`` false
    heads (Poisson) fall on cells of ``false_head_classes`` (tracks, ploughed furrows and
    plot-edge dead furrows look like incisions in a hillshade) that are at least
    ``false_head_clearance_m`` from every gully vertex. Only ``head_id`` reaches the file.

    Parameters
    ----------
    gullies : list of Gully
        The true network; the wadi is skipped.
    sigma : float
        Standard deviation of the position error per axis (m).
    crs : str
        Site CRS.
    seed : int
        Seed of the digitising random stream.
    vis : mapping
        ``twin.survey.heads_visibility`` (:data:`HEAD_VISIBILITY_KEYS`).
    u_exponent : float
        Cross-section exponent ``p`` of U-shaped gullies.
    landcover : ndarray or None
        Land-cover codes on ``grid``, for false heads; None gives no false heads.
    grid : GridSpec or None
        The grid of ``landcover``; None gives no false heads.

    Returns
    -------
    GeoDataFrame
        One point per digitised head with ``head_id`` (1, 2, ...), numbered west to east before
        the error is added.
    """
    rng = rng_for(seed, "twin", "digitised_heads")
    thr = vis["relief_k"] * vis["dsm_sigma_z_m"]
    res_m = vis["dsm_resolution_m"]
    min_run = vis["min_run_cells"] * res_m
    pts = []
    n_missed = n_marginal = 0
    for g in gullies:
        if g.kind == "wadi" or len(g.x) < 2:
            continue
        rel = resolved_relief(g.depth, g.width, shape_factor(g.shape, u_exponent), res_m)
        i = visible_head_index(g.s, rel, thr, min_run)
        if i < 0:
            n_missed += 1
            continue
        run = rel[i:]
        stop = np.argmax(run < thr) if (run < thr).any() else run.size
        if run[:stop].max() < 2.0 * thr and rng.uniform() < vis["marginal_miss_rate"]:
            n_marginal += 1
            continue
        pts.append((g.x[i], g.y[i]))
    n_true = len(pts)
    false_pts = _false_heads(gullies, vis, landcover, grid, rng)
    pts += false_pts
    log.info("digitised heads: %d seen, %d never visible (relief < %.2f m over %.1f m), %d marginal missed, %d false",
             n_true, n_missed, thr, min_run, n_marginal, len(false_pts))
    if not pts:
        return gpd.GeoDataFrame({"head_id": []}, geometry=[], crs=crs)
    h = np.asarray(pts, dtype=float)
    order = np.argsort(h[:, 0] + 1e-3 * h[:, 1])
    h = h[order] + rng.normal(0.0, sigma, h.shape)
    return gpd.GeoDataFrame({"head_id": np.arange(1, len(h) + 1)}, geometry=[Point(p) for p in h], crs=crs)


def _false_heads(gullies: list[Gully], vis: dict, landcover: np.ndarray | None, grid: GridSpec | None,
                 rng: np.random.Generator) -> list[tuple[float, float]]:
    """False heads on cells of ``false_head_classes`` away from the gullies (Poisson count)."""
    if landcover is None or grid is None or vis["false_heads_per_km2"] <= 0:
        return []
    area_km2 = grid.width * grid.height * grid.cell**2 / 1e6
    n = int(rng.poisson(vis["false_heads_per_km2"] * area_km2))
    if n == 0:
        return []
    step = max(1, int(round(1.0 / grid.cell)))  # candidates on a ~1 m lattice
    codes = [CODE[c] for c in vis["false_head_classes"]]
    r, c = np.nonzero(np.isin(landcover[::step, ::step], codes))
    if r.size == 0:
        return []
    xs, ys = grid.cell_centres()
    cx, cy = xs[::step][c], ys[::step][r]
    verts = np.concatenate([np.column_stack([g.x, g.y]) for g in gullies if len(g.x)])
    far = cKDTree(verts).query(np.column_stack([cx, cy]), k=1)[0] >= vis["false_head_clearance_m"]
    cx, cy = cx[far], cy[far]
    if cx.size == 0:
        return []
    pick = rng.choice(cx.size, size=min(n, cx.size), replace=False)
    return [(float(cx[k]), float(cy[k])) for k in pick]
