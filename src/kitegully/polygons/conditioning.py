"""DEM conditioning, sink fill, fill-depth masks and polygons (Höfle et al. 2013 sect. 4.1-4.2)."""

from __future__ import annotations

import logging

import geopandas as gpd
import numpy as np
import scipy.ndimage as ndi
import shapely
from rasterio import features

from kitegully.io.raster import GridSpec
from kitegully.terrain.fill import priority_flood_fill

log = logging.getLogger(__name__)


def line_cells(ln: shapely.LineString, grid: GridSpec) -> tuple[np.ndarray, np.ndarray]:
    """Rows and columns of the grid cells along a line, in order (a point every quarter cell; off-grid points dropped)."""
    if ln.is_empty or ln.length == 0:
        return np.zeros(0, int), np.zeros(0, int)
    s = np.arange(0.0, ln.length + 1e-9, 0.25 * grid.cell)
    pts = shapely.line_interpolate_point(ln, s)
    r, c = grid.rowcol(shapely.get_x(pts), shapely.get_y(pts))
    r, c = np.round(r).astype(int), np.round(c).astype(int)
    ok = (r >= 0) & (r < grid.height) & (c >= 0) & (c < grid.width)
    return r[ok], c[ok]


def rasterize_lines(lines: list[shapely.LineString], grid: GridSpec) -> np.ndarray:
    """Cells touched by the lines (points every quarter cell along each line)."""
    out = np.zeros((grid.height, grid.width), bool)
    for ln in lines:
        r, c = line_cells(ln, grid)
        out[r, c] = True
    return out


def bank_high_dams(lines: list[shapely.LineString], dem: np.ndarray, grid: GridSpec, grow_cells: int = 1) -> np.ndarray:
    """The DEM with every dam raised to its crest, the lower bank it spans, and no higher.

    A dam's crest is the lower of the highest ground on either side of the lowest point of
    its profile: a check dam across a channel holds water up to its lower bank, and a dam
    lying on open ground (no dip between two higher sides: a transect along a contour, or
    down a slope) holds none. The dam's cells and their ``grow_cells`` neighbours are raised
    to the crest where the ground is lower; where dams cross, the higher crest stands.

    Parameters
    ----------
    lines
        Dam lines (the clipped transects) in the grid's CRS.
    dem
        Elevations (m) on ``grid``; NaN = no data (left as is).
    grid
        The stage grid.
    grow_cells
        Dilation of each dam (cells), as the barrier raster's.

    Returns
    -------
    numpy.ndarray
        float64 DEM with the dams at their crests. O(Σ dam cells · (2·grow_cells + 1)²).
    """
    ground = np.asarray(dem, np.float64)
    out = ground.copy()
    h, w = out.shape
    off = np.arange(-grow_cells, grow_cells + 1)
    for ln in lines:
        r, c = line_cells(ln, grid)
        z = ground[r, c]  # each dam's own ground profile, not the crests of dams it crosses
        if not np.isfinite(z).any():
            continue
        lowest = int(np.nanargmin(z))
        crest = min(np.nanmax(z[: lowest + 1]), np.nanmax(z[lowest:]))
        rr, cc = np.broadcast_arrays(np.clip(r[:, None, None] + off[None, :, None], 0, h - 1),
                                     np.clip(c[:, None, None] + off[None, None, :], 0, w - 1))
        cur = out[rr, cc]
        out[rr, cc] = np.where(np.isfinite(cur), np.maximum(cur, crest), cur)
    return out


def bank_held_depth(lines: list[shapely.LineString], dem: np.ndarray, grid: GridSpec, grow_cells: int = 1) -> np.ndarray:
    """Water depth (m) the DEM holds with every dam only as high as its lower bank (:func:`bank_high_dams`).

    Returns float32, NaN on nodata. O(n log n) (one priority flood).

    Parameters
    ----------
    lines : list of LineString
        Dam lines (the clipped transects) in the grid's CRS.
    dem : ndarray (H, W)
        Elevations (m) on ``grid``; NaN = no data.
    grid : GridSpec
        The stage grid.
    grow_cells : int
        Dilation of each dam (cells).

    Returns
    -------
    ndarray (H, W) float32
        Water depth (m).
    """
    dammed = bank_high_dams(lines, dem, grid, grow_cells)
    filled, _ = priority_flood_fill(dammed, epsilon=0.0)
    return (filled - dammed).astype(np.float32)


def barrier_mask(breaklines: np.ndarray, transects: np.ndarray, grow_cells: int = 1) -> np.ndarray:
    """Breakline and transect cells grown by ``grow_cells`` in all 8 directions.

    Parameters
    ----------
    breaklines, transects : ndarray (H, W) bool
        Breakline cells and transect cells.
    grow_cells : int
        Number of 8-connected dilation steps (cells); 0 = no growth.

    Returns
    -------
    ndarray (H, W) bool
        Barrier cells.
    """
    m = breaklines | transects
    if grow_cells > 0:
        m = ndi.binary_dilation(m, structure=np.ones((3, 3), bool), iterations=grow_cells)
    return m


def fill_depth(dem: np.ndarray, barriers: np.ndarray, raise_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Raise the barriers by ``raise_m``, sink-fill (priority flood, level pools), FD = filled − conditioned.

    Returns (fill depth ≥ 0, NaN on nodata; conditioned DEM). O(n log n).

    Parameters
    ----------
    dem : ndarray (H, W)
        DEM (m), NaN nodata.
    barriers : ndarray (H, W) bool
        Cells to raise.
    raise_m : float
        Height added to the barrier cells (m).

    Returns
    -------
    fd : ndarray (H, W) float32
        Fill depth (m).
    conditioned : ndarray (H, W) float32
        The DEM with the barriers raised (m).
    """
    cond = np.asarray(dem, np.float64).copy()
    cond[barriers] += raise_m
    filled, n = priority_flood_fill(cond, epsilon=0.0)
    fd = filled - cond
    log.info("sink fill of the conditioned DEM: %d cells raised, max fill depth %.2f m", n, float(np.nanmax(fd)) if np.isfinite(fd).any() else 0.0)
    return fd.astype(np.float32), cond.astype(np.float32)


def gully_mask(fd: np.ndarray, threshold: float, closing_cells: int, min_area_m2: float, cell: float,
               seeds: np.ndarray | None = None, bridgeable: np.ndarray | None = None,
               edge_band: np.ndarray | None = None, edge_cells: int = 0, held: np.ndarray | None = None,
               rims: tuple | None = None, held_cells: bool = False, bank_held: np.ndarray | None = None) -> np.ndarray:
    """Label raster of the gully polygons at one fill-depth threshold.

    ``FD ≥ threshold``, closed with a ``closing_cells`` square (bridges barriers narrower
    than it), components smaller than ``min_area_m2`` dropped and, when
    ``seeds`` is given, only components touching a seed cell (the thalweg) kept. With
    ``bridgeable``, the closing may only add those cells (e.g. the transect dams that are
    not also breaklines), so that pools on either side of a breakline stay apart.
    With ``held`` (fill depth of the DEM with the dams alone, no breakline walls), only
    pools (components before the closing) in which the terrain itself holds water at least
    ``threshold`` deep are kept; with ``held_cells`` only the cells where it does (water that
    only the raised breakline walls hold, e.g. a field flooded beyond the rim where a gully's
    dams end, is not in the incision). With ``rims`` (breakline cells and their lower sides), only
    pools on the lower side of the upper edges they touch are kept
    (:func:`_pools_below_rims`): a compartment beyond the rims of the gullies around it is
    not an incision. With ``bank_held`` (:func:`bank_held_depth`: the water that dams no
    higher than their lower banks hold), only cells under such water (below the banks of a
    dammed channel) are kept, and only polygons in which it stands at least ``threshold``
    deep somewhere: a compartment that only the raised dams hold (crossing transects on a
    field) impounds no channel, and a field beside a gully that such a compartment joins to
    its pool lies above the gully's banks. With ``edge_band`` (the grown breakline cells) the mask then grows by
    ``edge_cells`` into that band: the barrier was widened only against diagonal leaks, the
    gully's outline is the breakline itself.

    Returns int32 labels (0 = not gully), numbered 1..n.

    Parameters
    ----------
    fd : ndarray (H, W)
        Fill depth (m), NaN read as 0.
    threshold : float
        Fill-depth threshold (m).
    closing_cells : int
        Side of the square closing element (cells); 1 or less = no closing.
    min_area_m2 : float
        Smallest component kept (m²).
    cell : float
        Cell size (m).
    seeds : ndarray (H, W) bool or None
        Seed cells (the thalweg) a component must touch.
    bridgeable : ndarray (H, W) bool or None
        The only cells the closing may add.
    edge_band : ndarray (H, W) bool or None
        Cells the mask may grow into (the grown breakline cells).
    edge_cells : int
        Growth into ``edge_band`` (cells); the rim test looks ``edge_cells + 2`` cells to each side.
    held : ndarray (H, W) or None
        Fill depth (m) of the DEM with the dams alone.
    rims : tuple or None
        ``(rows, cols, d_row, d_col)`` of the breakline cells (:func:`kitegully.polygons.breaklines.low_sides`).
    held_cells : bool
        Test ``held`` per cell instead of per pool.
    bank_held : ndarray (H, W) or None
        Water depth (m) held by dams no higher than their lower banks.

    Returns
    -------
    ndarray (H, W) int32
        Gully labels, 0 = not gully.
    """
    m = np.nan_to_num(fd, nan=0.0) >= threshold
    if held is not None and held_cells:
        m &= np.nan_to_num(held, nan=0.0) >= threshold
    elif held is not None:
        pools, npool = ndi.label(m, structure=np.ones((3, 3), bool))
        m = _touching(pools, npool, np.nan_to_num(held, nan=0.0) >= threshold)[pools]
    if bank_held is not None:
        m &= np.nan_to_num(bank_held, nan=0.0) > 0.0
    if rims is not None:
        m = _pools_below_rims(m, rims, edge_cells + 2)
    if edge_band is not None and edge_cells > 0:
        m |= ndi.binary_dilation(m, structure=np.ones((3, 3), bool), iterations=edge_cells) & edge_band
    if closing_cells > 1:
        se = np.ones((closing_cells, closing_cells), bool)
        pad = closing_cells
        closed = ndi.binary_closing(np.pad(m, pad), structure=se)[pad:-pad, pad:-pad]
        m = closed if bridgeable is None else m | (closed & bridgeable)
    lab, n = ndi.label(m, structure=np.ones((3, 3), bool))
    if n == 0:
        return lab.astype(np.int32)
    size = np.bincount(lab.ravel(), minlength=n + 1) * cell * cell
    keep = size >= min_area_m2
    if seeds is not None:
        keep &= _touching(lab, n, seeds)
    if bank_held is not None:
        keep &= _touching(lab, n, np.nan_to_num(bank_held, nan=0.0) >= threshold)  # impounds a channel
    keep[0] = False
    new = np.zeros(n + 1, np.int32)
    new[keep] = np.arange(1, keep.sum() + 1, dtype=np.int32)
    return new[lab]


def _touching(lab: np.ndarray, n: int, cells: np.ndarray) -> np.ndarray:
    """Per label 0..n, True where the component holds at least one of ``cells`` (label 0: False)."""
    hit = np.zeros(n + 1, bool)
    hit[np.unique(lab[cells & (lab > 0)])] = True
    hit[0] = False
    return hit


def _pools_below_rims(m: np.ndarray, rims: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray], reach: int) -> np.ndarray:
    """Keep pools that lie on the lower side of most of the breakline cells they touch.

    ``rims`` = (rows, cols, d_row, d_col) from :func:`kitegully.polygons.breaklines.low_sides`.
    Each breakline cell looks ``reach`` cells to its lower and to its higher side; a pool
    seen more often from above (it is the incision below those upper edges) than from
    below (it is terrain beyond them) is kept; pools no breakline sees are kept (open pools).
    """
    pools, n = ndi.label(m, structure=np.ones((3, 3), bool))
    rr, cc, dr, dc = rims
    if n == 0 or rr.size == 0:
        return m
    h, w = m.shape

    def look(sign):
        r = np.clip(np.round(rr + sign * reach * dr).astype(int), 0, h - 1)
        c = np.clip(np.round(cc + sign * reach * dc).astype(int), 0, w - 1)
        return pools[r, c]

    below = np.bincount(look(1.0), minlength=n + 1)
    above = np.bincount(look(-1.0), minlength=n + 1)
    keep = below >= above
    keep[0] = False
    return keep[pools]


def polygons_from_labels(labels: np.ndarray, grid: GridSpec, threshold: float,
                         fd: np.ndarray | None = None) -> gpd.GeoDataFrame:
    """Vectorise a label raster: one polygon per label with area (m²) and mean fill depth (m).

    Parameters
    ----------
    labels : ndarray (H, W) int32
        Label raster, 0 = background.
    grid : GridSpec
        Grid of ``labels``.
    threshold : float
        Fill-depth threshold (m) written to each row.
    fd : ndarray (H, W) or None
        Fill depth (m), NaN read as 0; without it there is no ``mean_fill_depth_m`` column.

    Returns
    -------
    GeoDataFrame
        ``polygon_id, threshold_m, area_m2`` (and ``mean_fill_depth_m``) and the polygon, in the grid's CRS.
    """
    geoms: dict[int, list] = {}
    for geom, val in features.shapes(labels, mask=labels > 0, transform=grid.transform, connectivity=8):
        geoms.setdefault(int(val), []).append(shapely.geometry.shape(geom))
    ids = sorted(geoms)
    polys = [shapely.union_all(geoms[i]) for i in ids]
    recs = {"polygon_id": ids, "threshold_m": [threshold] * len(ids), "area_m2": [p.area for p in polys]}
    if fd is not None and len(ids):
        idx = np.asarray(ids)
        fdv = np.nan_to_num(fd, nan=0.0)
        recs["mean_fill_depth_m"] = (ndi.sum(fdv, labels, idx) / np.maximum(ndi.sum(np.ones_like(fdv), labels, idx), 1)).tolist()
    return gpd.GeoDataFrame(recs, geometry=polys, crs=grid.crs)
