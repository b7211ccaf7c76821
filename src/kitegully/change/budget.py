"""Erosion, deposition and net volume with two uncertainty estimates, segregated by masks.

Volumes: erosion = Σ max(−DoD, 0)·a and deposition = Σ max(DoD, 0)·a over the counted cells
(a = cell area), net = deposition − erosion (m³; negative = net loss of soil).

Uncertainty of the net volume, side by side:

* **independent cells** (GCD): σ_V = a·√(Σ σ_DoD,i²), which assumes every cell's error is
  independent and so shrinks like 1/√n;
* **spatially correlated** (Rolstad et al. 2009; Hugonnet et al. 2022): the empirical
  variogram of the co-registered dh on stable ground (standardised by σ_DoD), fitted by a
  nugget plus a spherical model of range r; the variance of the mean over an area A is
  σ̄²·[f₀·a/A + f₁·F(A, r)], with f₀, f₁ the nugget and spherical shares of the sill and,
  for a disc of the same area (L = √(A/π)), F = r²/(5L²) when L ≥ r and
  F = 1 − L/r + L³/(5r³) otherwise. σ_V = A·σ_mean.
* **co-registration**: the vertical offset is fitted on the stable cells only, so its own
  error (σ̄·√(mean correlation of the stable cells' pairs)) is shared by every cell:
  A·σ_offset. ``net_sd_m3`` = √(correlated² + co-registration²).

Masks: vector layers (each polygon value of a ``by`` column a budget row, plus their
union) and class rasters (each class a row), e.g. gully polygons, the bare-soil map,
land-cover classes and user polygons.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
import pandas as pd
import shapely
from affine import Affine
from rasterio import features
from scipy import optimize
from scipy.spatial.distance import pdist

from kitegully import InputError
from kitegully.io.raster import GridSpec, Raster
from kitegully.io.vectors import read_vector
from kitegully.seeds import rng_for

log = logging.getLogger(__name__)


# ----------------------------------------------------------------------------- masks


@dataclass
class MaskGroup:
    """One budget row's cells: ``name`` (``mask`` or ``mask:value``) and a boolean map.

    ``local`` is the map on the block ``rows, cols`` of a grid of ``shape`` (the whole grid
    when ``shape`` is None): a polygon of a ``by`` column covers a few hundred cells of a
    tile of millions, and a full map per polygon (2688 gully polygons × 5.3 M cells on a
    full-size tile: 14 GB) is what the block avoids. ``mask`` gives the full map.
    ``order`` places the row among its mask's rows (the ``by`` value's rank of a vector
    mask, the class value of a raster mask; -inf for the union): tiles of a site (issue 21)
    merge their rows in the order of the untiled table.
    """

    name: str
    local: np.ndarray
    source: str
    order: float = float("-inf")
    rows: slice = field(default_factory=lambda: slice(None))
    cols: slice = field(default_factory=lambda: slice(None))
    shape: tuple[int, int] | None = None

    @property
    def mask(self) -> np.ndarray:
        """The group's cells on the whole grid (allocates a full boolean map for a block group)."""
        if self.shape is None:
            return self.local
        out = np.zeros(self.shape, bool)
        out[self.rows, self.cols] = self.local
        return out

    def block(self, a: np.ndarray) -> np.ndarray:
        """``a`` (on the whole grid) on the group's block; ``a[g.mask]`` == ``g.block(a)[g.local]``, same order."""
        return a[self.rows, self.cols]


def _bounds_block(bounds: tuple[float, float, float, float], grid: GridSpec) -> tuple[slice, slice]:
    """Rows and columns of the cells whose centres can lie inside ``bounds`` (one cell of margin, clipped)."""
    xmin, ymin, xmax, ymax = bounds
    c0 = int(np.clip(np.floor((xmin - grid.x0) / grid.cell) - 1, 0, grid.width))
    c1 = int(np.clip(np.ceil((xmax - grid.x0) / grid.cell) + 1, c0, grid.width))
    r0 = int(np.clip(np.floor((grid.y0 - ymax) / grid.cell) - 1, 0, grid.height))
    r1 = int(np.clip(np.ceil((grid.y0 - ymin) / grid.cell) + 1, r0, grid.height))
    return slice(r0, r1), slice(c0, c1)


def _clip(geoms: np.ndarray, grid: GridSpec) -> np.ndarray:
    """``geoms`` clipped to the grid plus one cell (empty where they miss it).

    A cell centre lies half a cell inside the grid's edge, so a centre is inside a clipped
    polygon exactly when it is inside the polygon: the rasterised cells are the same.
    """
    xmin, ymin, xmax, ymax = grid.bounds
    m = grid.cell
    out = np.full(len(geoms), shapely.Polygon(), dtype=object)
    if len(geoms):
        hit = shapely.intersects(geoms, shapely.box(xmin - m, ymin - m, xmax + m, ymax + m))
        if hit.any():
            out[hit] = shapely.clip_by_rect(geoms[hit], xmin - m, ymin - m, xmax + m, ymax + m)
    return out[~shapely.is_empty(out)] if len(out) else out


#: Vertices above which :func:`_rasterise` splits the grid in two ([I] GDAL fills a polygon
#: scanline by scanline over all its edges, O(rows · edges): one bare-soil polygon of the
#: full-size site has 2.55 M vertices and 78 000 holes and took tens of minutes on one
#: 500 m tile; halving the grid and clipping keeps each call at O(rows · 50 000)).
SPLIT_VERTICES = 50_000

#: Offset (m, east and south) of the point each cell is tested at against the polygons [I]. Polygons made from a
#: finer raster (the kite bare-soil map: 0.1 m cells on a 0.2 m DoD grid) have edges through the DoD's cell
#: centres, and GDAL settles a centre lying exactly on an edge differently in different windows (a tile, a half of
#: a split grid, the whole grid: 460 stable cells of the full-size corner). 0.1 mm is far above the rounding of
#: projected coordinates (~1e-10 m) and far below any cell, so every window decides alike.
TIE_SHIFT_M = 1e-4


def _rasterise(geoms: Sequence[Any], grid: GridSpec) -> np.ndarray:
    """Cells of ``grid`` whose centres lie inside any of ``geoms`` (GDAL's rasterize, no all-touched; each centre
    tested :data:`TIE_SHIFT_M` east and south of itself, so that a centre on an edge is decided alike in any window).

    Large layers are clipped to the grid, then, while they hold more than
    :data:`SPLIT_VERTICES` vertices and the grid is larger than 64 cells, the grid is halved
    along its longer side and each half rasterised from the geometries clipped to it: the
    same cells as one call (every centre is tested against the same polygon), in
    O(V log V + cells) instead of O(rows · V) for V vertices.
    """
    geoms = _clip(np.asarray([g for g in geoms if g is not None and not g.is_empty], dtype=object), grid)
    out = np.zeros((grid.height, grid.width), bool)
    if not len(geoms):
        return out
    if shapely.get_num_coordinates(geoms).sum() > SPLIT_VERTICES and max(grid.height, grid.width) > 64:
        if grid.height >= grid.width:
            h = grid.height // 2
            out[:h] = _rasterise(geoms, grid.window(0, 0, h, grid.width))
            out[h:] = _rasterise(geoms, grid.window(h, 0, grid.height - h, grid.width))
        else:
            w = grid.width // 2
            out[:, :w] = _rasterise(geoms, grid.window(0, 0, grid.height, w))
            out[:, w:] = _rasterise(geoms, grid.window(0, w, grid.height, grid.width - w))
        return out
    shifted = Affine.translation(TIE_SHIFT_M, -TIE_SHIFT_M) * grid.transform
    return features.rasterize(((g, 1) for g in geoms), out_shape=out.shape, transform=shifted,
                              fill=0, dtype="uint8").astype(bool)


def _vector_groups(spec: Mapping[str, Any], grid: GridSpec) -> list[MaskGroup]:
    gdf = read_vector(spec["file"], crs=grid.crs)
    name, by = spec["name"], spec.get("by")
    gdf = gdf[gdf.geometry.notna() & ~gdf.geometry.is_empty]
    shape = (grid.height, grid.width)
    geoms = np.asarray(gdf.geometry.values, dtype=object)
    out = [MaskGroup(name, _rasterise(geoms, grid), str(spec["file"]))]
    if by:
        if by not in gdf.columns:
            raise InputError(f"{spec['file']}: mask '{name}' has no column '{by}' (columns: {', '.join(map(str, gdf.columns))})")
        grouped = gdf.groupby(by, sort=True)
        for i, (value, _) in enumerate(grouped):
            part = _clip(geoms[grouped.indices[value]], grid)
            if len(part):
                rs, cs = _bounds_block(tuple(shapely.total_bounds(part)), grid)
            else:
                rs, cs = slice(0, 0), slice(0, 0)
            h, w = rs.stop - rs.start, cs.stop - cs.start
            m = _rasterise(part, grid.window(rs.start, cs.start, h, w)) if h and w else np.zeros((h, w), bool)
            out.append(MaskGroup(f"{name}:{value}", m, str(spec["file"]), float(i), rs, cs, shape))
    return out


def _raster_groups(spec: Mapping[str, Any], grid: GridSpec) -> list[MaskGroup]:
    r = Raster.read(spec["file"])
    if r.crs != grid.crs:
        from rasterio.crs import CRS
        if CRS.from_user_input(r.crs) != CRS.from_user_input(grid.crs):
            raise InputError(f"{spec['file']}: CRS {r.crs} differs from the DEM's {grid.crs}")
    xs, ys = grid.cell_centres()
    rows, _ = r.grid.rowcol(np.zeros(1), ys)
    _, cols = r.grid.rowcol(xs, np.zeros(1))
    ri, ci = np.rint(rows).astype(int), np.rint(cols).astype(int)
    inside = (ri[:, None] >= 0) & (ri[:, None] < r.grid.height) & (ci[None, :] >= 0) & (ci[None, :] < r.grid.width)
    vals = r.data[np.clip(ri, 0, r.grid.height - 1)[:, None], np.clip(ci, 0, r.grid.width - 1)[None, :]]
    ok = inside & (r.valid[np.clip(ri, 0, r.grid.height - 1)[:, None], np.clip(ci, 0, r.grid.width - 1)[None, :]])
    names: dict[Any, str] = {}
    if spec.get("classes"):
        cls = pd.read_csv(spec["classes"]).rename(columns={"code": "value"})
        if not {"value", "name"} <= set(cls.columns):
            raise InputError(f"{spec['classes']}: class table needs columns value (or code),name")
        names = {int(v): str(n) for v, n in zip(cls["value"], cls["name"])}
    wanted = spec.get("values")
    out = []
    for v in np.unique(vals[ok]):
        if wanted is not None and int(v) not in wanted and names.get(int(v)) not in wanted:
            continue
        out.append(MaskGroup(f"{spec['name']}:{names.get(int(v), int(v))}", ok & (vals == v), str(spec["file"]), float(v)))
    union = np.zeros(vals.shape, bool)
    for g in out:
        union |= g.mask
    return [MaskGroup(spec["name"], union, str(spec["file"]))] + out


def mask_groups(specs: Sequence[Mapping[str, Any]], grid: GridSpec) -> list[MaskGroup]:
    """Rasterise every budget mask onto ``grid``; the whole site comes first as ``site``."""
    out = [MaskGroup("site", np.ones((grid.height, grid.width), bool), "DEM overlap")]
    for spec in specs:
        if not Path(spec["file"]).exists():
            raise InputError(f"{spec['file']}: mask '{spec['name']}' file not found")
        kind = spec.get("kind") or ("raster" if str(spec["file"]).lower().endswith((".tif", ".tiff")) else "vector")
        groups = _raster_groups(spec, grid) if kind == "raster" else _vector_groups(spec, grid)
        log.info("mask %s: %d groups, union %.0f m²", spec["name"], len(groups) - 1, groups[0].local.sum() * grid.cell**2)
        out += groups
    return out


def unstable_union(specs: Sequence[Mapping[str, Any]], groups: Sequence[MaskGroup], shape: tuple[int, int]) -> np.ndarray:
    """Union of the masks flagged ``unstable`` (excluded from stable ground).

    Parameters
    ----------
    specs : sequence of mapping
        The budget mask specs; a mask is flagged by a true ``unstable`` key.
    groups : sequence of MaskGroup
        The rasterised groups (:func:`mask_groups`); a flagged mask's union group is used.
    shape : tuple of int
        Shape ``(H, W)`` of the grid (cells).

    Returns
    -------
    ndarray (H, W) bool
        Cells of the flagged masks.
    """
    return _flagged_union(specs, groups, shape, "unstable")


def _flagged_union(specs: Sequence[Mapping[str, Any]], groups: Sequence[MaskGroup], shape: tuple[int, int],
                   flag: str) -> np.ndarray:
    """Union of the union groups of the masks whose spec has a true ``flag`` key."""
    flagged = {s["name"] for s in specs if s.get(flag)}
    out = np.zeros(shape, bool)
    for g in groups:
        if g.name in flagged:
            out[g.rows, g.cols] |= g.local
    return out


def stable_candidates(specs: Sequence[Mapping[str, Any]], groups: Sequence[MaskGroup], shape: tuple[int, int],
                      unstable: np.ndarray | None = None) -> np.ndarray:
    """Cells that may serve as stable ground: inside the masks flagged ``stable`` where there are any, else
    outside the masks flagged ``unstable`` (:func:`unstable_union`).

    A surveyor who knows where the ground did not change and looks like the ground being
    measured (a track among ploughed fields, a bare patch kept out of the plough) flags
    those polygons ``stable``: the co-registration and the variogram then use only them,
    even where an unstable mask covers them too (a kite bare-soil map includes the tracks).
    Voids and above-ground objects are removed by the caller. The error model's unchanged
    cells are not restricted (it needs the whole range of terrain).

    Parameters
    ----------
    specs : sequence of mapping
        The budget mask specs; a mask is flagged by a true ``stable`` or ``unstable`` key.
    groups : sequence of MaskGroup
        The rasterised groups (:func:`mask_groups`); a flagged mask's union group is used.
    shape : tuple of int
        Shape ``(H, W)`` of the grid (cells).
    unstable : ndarray (H, W) bool, optional
        :func:`unstable_union` of the same masks where the caller has it already.

    Returns
    -------
    ndarray (H, W) bool
        The candidate cells.

    Raises
    ------
    InputError
        A mask flagged both stable and unstable.
    """
    both = [s["name"] for s in specs if s.get("stable") and s.get("unstable")]
    if both:
        raise InputError(f"change.masks: {both[0]} is flagged both stable and unstable; choose one")
    if not any(s.get("stable") for s in specs):
        return ~(unstable_union(specs, groups, shape) if unstable is None else unstable)
    return _flagged_union(specs, groups, shape, "stable")


# ----------------------------------------------------------------------------- variogram


@dataclass
class Variogram:
    """Nugget + sum of sphericals of standardised dh: γ(h) = c₀ + Σ cₖ·sph(h/rₖ) (Hugonnet's multi-range model)."""

    nugget: float
    sills: tuple[float, ...]
    ranges_m: tuple[float, ...]
    empirical: pd.DataFrame

    @property
    def total(self) -> float:
        """Total sill: the nugget plus the spherical sills (at least 1e-12)."""
        return max(self.nugget + sum(self.sills), 1e-12)

    @property
    def f_nugget(self) -> float:
        """The nugget as a fraction of the total sill."""
        return self.nugget / self.total

    def model(self, h: np.ndarray) -> np.ndarray:
        """Modelled semivariance at lags ``h``.

        Parameters
        ----------
        h : ndarray
            Lags (m).

        Returns
        -------
        ndarray
            ``c₀ + Σ cₖ·sph(h/rₖ)``, in the units of the empirical semivariance.
        """
        h = np.asarray(h, float)
        return self.nugget + sum(c * spherical(h, r) for c, r in zip(self.sills, self.ranges_m))

    def describe(self) -> str:
        """One line for the log: the nugget and each spherical's sill and range (m)."""
        parts = ", ".join(f"{c:.3f} at {r:.1f} m" for c, r in zip(self.sills, self.ranges_m))
        return f"nugget {self.nugget:.3f}, spherical {parts}"


def spherical(h: np.ndarray, r: float) -> np.ndarray:
    """Unit-sill spherical variogram."""
    u = np.clip(h / r, 0.0, 1.0)
    return 1.5 * u - 0.5 * u**3


def empirical_variogram(z: np.ndarray, grid: GridSpec, ok: np.ndarray, max_lag_m: float, bins: int,
                        samples: int, seed: int) -> pd.DataFrame:
    """Semivariance of ``z`` on cells ``ok`` by lag.

    Short lags (up to 64 cells, doubling) come from every pair of ``ok`` cells at that row
    and column offset; longer lags from all pairs of ``samples`` random ``ok`` cells, binned.
    O(cells · log 64 + samples²).

    Parameters
    ----------
    z : ndarray (H, W)
        The field, e.g. standardised dh; non-finite cells are left out.
    grid : GridSpec
        Grid of ``z``; its cell size (m) sets the lags.
    ok : ndarray (H, W) bool
        Cells to use.
    max_lag_m : float
        Longest lag (m).
    bins : int
        Number of long-lag bins, from the last short lag to ``max_lag_m``.
    samples : int
        Most random cells for the long lags.
    seed : int
        Master seed of the random subset.

    Returns
    -------
    DataFrame
        One row per lag with enough pairs: ``lag_m`` (m), ``semivariance`` and ``pairs``.
    """
    rows = []
    k = 1
    while k <= 64 and k * grid.cell < max_lag_m:
        d = []
        for a, b, oa in ((z[:, k:], z[:, :-k], ok[:, k:] & ok[:, :-k]), (z[k:, :], z[:-k, :], ok[k:, :] & ok[:-k, :])):
            d.append((a - b)[oa])
        d = np.concatenate(d)
        d = d[np.isfinite(d)]
        if d.size > 10:
            rows.append((k * grid.cell, 0.5 * float(np.mean(d**2)), int(d.size)))
        k *= 2
    idx = np.flatnonzero(ok & np.isfinite(z))
    if idx.size > samples:
        idx = rng_for(seed, "change", "variogram").choice(idx, samples, replace=False)
    if idx.size >= 10:
        r, c = np.unravel_index(idx, z.shape)
        pts = np.stack([c * grid.cell, r * grid.cell], axis=1)
        h = pdist(pts)
        g = 0.5 * pdist(z.ravel()[idx][:, None], "sqeuclidean")
        start = rows[-1][0] if rows else 0.0
        edges = np.linspace(start, max_lag_m, bins + 1)
        which = np.digitize(h, edges) - 1
        for i in range(bins):
            sel = which == i
            if sel.sum() >= 30:
                rows.append((float(h[sel].mean()), float(g[sel].mean()), int(sel.sum())))
    return pd.DataFrame(rows, columns=["lag_m", "semivariance", "pairs"])


def fit_variogram(emp: pd.DataFrame, cell: float, max_lag_m: float) -> Variogram:
    """Weighted (√pairs) least-squares fit of a nugget plus one and two sphericals; the better one.

    Ranges lie in [cell, max_lag]; the two-range model (short: noise and texture, long:
    georeferencing and correlated matching errors) is kept when it converges with a lower
    weighted misfit, as in Hugonnet et al. (2022).

    Parameters
    ----------
    emp : DataFrame
        Empirical variogram (:func:`empirical_variogram`): ``lag_m``, ``semivariance``, ``pairs``.
    cell : float
        Cell size (m), the shortest range.
    max_lag_m : float
        Longest range (m).

    Returns
    -------
    Variogram
        The better model, its sphericals sorted by range; ``emp`` is its ``empirical`` table.
    """
    if len(emp) < 4:
        raise ValueError("too few variogram lags to fit a model")
    h, g, w = emp["lag_m"].to_numpy(), emp["semivariance"].to_numpy(), np.sqrt(emp["pairs"].to_numpy())
    top = float(g.max())
    best: tuple[float, Variogram] | None = None

    def f1(hh, c0, c1, r1):
        return c0 + c1 * spherical(hh, r1)

    def f2(hh, c0, c1, r1, c2, r2):
        return c0 + c1 * spherical(hh, r1) + c2 * spherical(hh, r2)

    starts1 = [[g[0] * 0.5, top / 2, r] for r in (2 * cell, max_lag_m / 10, max_lag_m / 3)]
    starts2 = [[g[0] * 0.3, top / 3, r1, top / 3, r2] for r1, r2 in ((2 * cell, max_lag_m / 5), (5 * cell, max_lag_m / 2))]
    for fn, starts, k in ((f1, starts1, 1), (f2, starts2, 2)):
        lo = [0.0] + [0.0, cell] * k
        hi = [2 * top] + [2 * top, max_lag_m] * k
        for p0 in starts:
            try:
                p, _ = optimize.curve_fit(fn, h, g, p0=np.clip(p0, lo, hi), sigma=1 / w, bounds=(lo, hi), maxfev=20000)
            except (RuntimeError, ValueError):
                continue
            sse = float(np.sum((w * (fn(h, *p) - g)) ** 2))
            comps = sorted(zip(p[1::2], p[2::2]), key=lambda cr: cr[1])
            vg = Variogram(float(p[0]), tuple(float(c) for c, _ in comps), tuple(float(r) for _, r in comps), emp)
            if best is None or sse < best[0] * (0.98 if k == 2 else 1.0):
                best = (sse, vg)
    if best is None:
        raise RuntimeError("variogram fit did not converge")
    return best[1]


def correlation_factor(area_m2: float, cell: float, vg: Variogram) -> float:
    """Variance of the mean of a unit-σ field over an area, relative to one cell's variance.

    Nugget share × a/A plus, per spherical, its share × F(A, r) (Rolstad et al. 2009, disc
    of the same area).

    Parameters
    ----------
    area_m2 : float
        The area A (m²).
    cell : float
        Cell size (m); a is its square.
    vg : Variogram
        The fitted model.

    Returns
    -------
    float
        The factor; NaN when ``area_m2`` is not positive.
    """
    if area_m2 <= 0:
        return float("nan")
    a = cell * cell
    L = np.sqrt(area_m2 / np.pi)
    out = vg.f_nugget * min(1.0, a / area_m2)
    for c, r in zip(vg.sills, vg.ranges_m):
        f = r * r / (5 * L * L) if L >= r else 1 - L / r + L**3 / (5 * r**3)
        out += c / vg.total * f
    return float(out)


def mean_correlation(rows: np.ndarray, cols: np.ndarray, cell: float, vg: Variogram, samples: int, seed: int) -> float:
    """Mean correlation ρ(h) = 1 − γ(h)/sill over all pairs of the given cells (a random subset).

    Var(mean of n unit-σ cells) ≈ this mean for large n; it is the offset-estimate variance
    of a co-registration fitted on exactly these (scattered) cells. O(samples²).

    Parameters
    ----------
    rows, cols : ndarray
        Row and column indices of the cells.
    cell : float
        Cell size (m).
    vg : Variogram
        The fitted model.
    samples : int
        Most cells used; more are subsampled at random.
    seed : int
        Master seed of the random subset.

    Returns
    -------
    float
        The mean ρ (at least 0) plus 1/n for the n cells used; 1.0 for fewer than two cells.
    """
    if rows.size < 2:
        return 1.0
    if rows.size > samples:
        pick = rng_for(seed, "change", "coreg_sd").choice(rows.size, samples, replace=False)
        rows, cols = rows[pick], cols[pick]
    h = pdist(np.stack([cols * cell, rows * cell], axis=1))
    rho = 1.0 - vg.model(h) / vg.total
    return float(max(np.mean(rho), 0.0) + 1.0 / rows.size)


# ----------------------------------------------------------------------------- budgets


def budget_row(dod: np.ndarray, sigma: np.ndarray, counted: np.ndarray, cell: float, vg: Variogram | None,
               coreg_sd_m: float = 0.0) -> dict[str, float]:
    """Volumes and net uncertainties of the cells ``counted`` (valid DoD cells).

    ``coreg_sd_m``: SD of the co-registration's vertical offset, an error shared by every
    cell (adds A·σ_offset in quadrature to the correlated SD).

    Parameters
    ----------
    dod : ndarray (H, W)
        DEM of difference (m).
    sigma : ndarray (H, W)
        σ_DoD of each cell (m).
    counted : ndarray (H, W) bool
        Cells to count; those with a non-finite DoD or σ are left out.
    cell : float
        Cell size (m).
    vg : Variogram or None
        Model of the standardised dh; None gives a NaN correlated SD.
    coreg_sd_m : float
        See above (m).

    Returns
    -------
    dict
        ``area_m2``, ``erosion_m3``, ``deposition_m3``, ``net_m3``, ``net_sd_m3``, ``net_sd_independent_m3``,
        ``net_sd_correlated_m3``, ``net_sd_coregistration_m3`` and ``mean_dh_m``.
    """
    return budget_row_from_sums(budget_sums(dod, sigma, counted), cell, vg, coreg_sd_m)


def budget_sums(dod: np.ndarray, sigma: np.ndarray, counted: np.ndarray) -> tuple[int, float, float, float]:
    """The sums a budget row needs over the cells ``counted`` with a finite DoD and σ.

    Returns ``(n, Σ max(−DoD, 0), Σ max(DoD, 0), Σ σ²)`` (float64 sums, m and m²); sums of
    disjoint parts (tiles) add up to the whole's (up to the order of floating-point sums).

    Parameters
    ----------
    dod : ndarray (H, W)
        DEM of difference (m).
    sigma : ndarray (H, W)
        σ_DoD of each cell (m).
    counted : ndarray (H, W) bool
        Cells to count.

    Returns
    -------
    n : int
        Number of cells summed.
    erosion, deposition : float
        Σ max(−DoD, 0) and Σ max(DoD, 0) (m).
    sigma2 : float
        Σ σ² (m²).
    """
    c = counted & np.isfinite(dod) & np.isfinite(sigma)
    d, s = dod[c].astype(np.float64), sigma[c].astype(np.float64)
    return int(c.sum()), float(np.sum(np.clip(-d, 0, None))), float(np.sum(np.clip(d, 0, None))), float(np.sum(s**2))


def budget_row_from_sums(sums: tuple[int, float, float, float], cell: float, vg: Variogram | None,
                         coreg_sd_m: float = 0.0) -> dict[str, float]:
    """:func:`budget_row` from :func:`budget_sums` (of the whole area, e.g. summed over tiles).

    Parameters
    ----------
    sums : tuple of (int, float, float, float)
        ``(n, Σ max(−DoD, 0), Σ max(DoD, 0), Σ σ²)`` (m and m²).
    cell : float
        Cell size (m).
    vg : Variogram or None
        Model of the standardised dh; None gives a NaN correlated SD.
    coreg_sd_m : float
        SD of the co-registration's vertical offset (m).

    Returns
    -------
    dict
        The columns of :func:`budget_row`.
    """
    n, ero_sum, dep_sum, s2_sum = sums
    a = cell * cell
    ero = float(ero_sum * a)
    dep = float(dep_sum * a)
    area = float(n * a)
    sd_ind = float(a * np.sqrt(s2_sum))
    sd_cor = float(area * np.sqrt(s2_sum / n * correlation_factor(area, cell, vg))) if (vg is not None and area > 0) else float("nan")
    sd_reg = float(area * coreg_sd_m)
    base = sd_cor if np.isfinite(sd_cor) else sd_ind
    return dict(area_m2=area, erosion_m3=ero, deposition_m3=dep, net_m3=dep - ero,
                net_sd_m3=float(np.hypot(base, sd_reg)), net_sd_independent_m3=sd_ind,
                net_sd_correlated_m3=sd_cor, net_sd_coregistration_m3=sd_reg,
                mean_dh_m=(dep - ero) / area if area > 0 else float("nan"))


def compute_budgets(dod: np.ndarray, sigma: np.ndarray, detected: Mapping[str, np.ndarray], groups: Sequence[MaskGroup],
                    cell: float, vg: Variogram | None, coreg_sd_m: float = 0.0) -> pd.DataFrame:
    """One row per (mask, method); method ``raw`` counts every valid cell of the mask.

    ``net_sd_m3`` = √(correlated² + co-registration²) (the independent-cell SD where no
    variogram was fitted).

    Parameters
    ----------
    dod : ndarray (H, W)
        DEM of difference (m); its finite cells are the valid ones.
    sigma : ndarray (H, W)
        σ_DoD of each cell (m).
    detected : mapping
        Detection method name to its ndarray (H, W) bool map of detected cells; one row each.
    groups : sequence of MaskGroup
        The budget masks (:func:`mask_groups`).
    cell : float
        Cell size (m).
    vg : Variogram or None
        Model of the standardised dh; None gives a NaN correlated SD.
    coreg_sd_m : float
        SD of the co-registration's vertical offset (m), shared by every cell.

    Returns
    -------
    DataFrame
        Columns ``mask``, ``method``, the :func:`budget_row` columns and ``mask_area_m2`` (the mask's valid cells, m²).
    """

    valid = np.isfinite(dod)
    rows = []
    for g in groups:
        inside = g.local & g.block(valid)
        d, s = g.block(dod), g.block(sigma)
        for method, det in [("raw", valid), *detected.items()]:
            row = dict(mask=g.name, method=method, mask_area_m2=float(inside.sum() * cell * cell))
            row.update(budget_row(d, s, inside & g.block(det), cell, vg, coreg_sd_m))
            rows.append(row)
    cols = ["mask", "method", "erosion_m3", "deposition_m3", "net_m3", "net_sd_m3", "net_sd_independent_m3",
            "net_sd_correlated_m3", "net_sd_coregistration_m3", "area_m2", "mask_area_m2", "mean_dh_m"]
    return pd.DataFrame(rows)[cols]
