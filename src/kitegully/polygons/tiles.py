"""Morphometry of a tiled site's polygons as tile jobs (issue 21): ownership, windows, merge.

On a site with a ``tiling:`` section, ``polygons_map`` stops before step 6 (it writes the
labels at the morphometry threshold, the pool level and the rim band), each tile job
measures the polygons it *owns* — those whose centroid lies in its cells (the tiles
partition the stage grid, so each polygon has exactly one owner) — and one merge job joins
the parts in polygon order.

A tile job reads only a window: the union of its polygons' bounding boxes plus
:func:`margin_cells` (a section reaches ``rim_search_m`` beyond the polygon for its rim, ``bank_fit_m``
beyond that for the bank reference and ``ground_segment_m`` beyond that for its ground profile, plus
the bilinear drape's cell).
Every polygon is measured on its own (:func:`kitegully.polygons.morphometry.measure_sections`
uses only its label, its outline and the rasters along its sections), and the window maps
map coordinates to cells exactly as the whole grid does (:class:`WindowGrid`: the whole
grid's fractional row and column minus a whole number, an exact float subtraction), so the
merged products equal the whole-grid morphometry bit for bit. (A grid with its origin
moved to the window's corner is not enough: its rounding differs in the last bit; and the
window starts on an even row and column, because the rim search rounds sample positions
to cells, halves to even, so a sample exactly between two cells would go to the other
cell in a window at an odd offset, and its section's depth change by centimetres: found
on the default site, 8 of 51 polygons.)

Measured at the full Kamech size (12.7 M cells at 0.5 m, 577 polygons at t = 0.5 m;
``benchmarks/polygons_scale.py``): step 6 is 45 s of the stage's ~100 s, the step that
dominates once the transects' quadratic floor was removed; the steps before it stay one
job (see README "Stage 6b").
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from math import ceil
from pathlib import Path
from typing import Callable, Iterable

import geopandas as gpd
import numpy as np
import pandas as pd

from kitegully.io.raster import GridSpec
from kitegully.polygons.stage import PolygonParams, measure_morphometry, morphometry_rows
from kitegully.terrain.tiled_fill import Tile

log = logging.getLogger(__name__)

#: The rasters a tile job reads (written by ``polygons_map`` on tiled sites).
WINDOW_RASTERS = ("labels", "dem", "level", "rims")


@dataclass(frozen=True)
class WindowGrid(GridSpec):
    """A window of a grid (``GridSpec`` of the window) whose cell arithmetic is the parent's.

    :meth:`rowcol` is the parent grid's fractional (row, col) minus the window's whole
    offset, and :meth:`xy` the parent's at the offset cell: bit for bit the numbers the
    whole grid gives, shifted.
    """

    parent_x0: float = 0.0
    parent_y0: float = 0.0
    row0: int = 0
    col0: int = 0

    @classmethod
    def of(cls, grid: GridSpec, r0: int, c0: int, h: int, w: int) -> "WindowGrid":
        """The window ``rows r0:r0+h, cols c0:c0+w`` of ``grid``.

        Parameters
        ----------
        grid : GridSpec
            The parent grid.
        r0, c0 : int
            Top-left cell of the window in ``grid``.
        h, w : int
            Rows and columns of the window.

        Returns
        -------
        WindowGrid
        """
        g = grid.window(r0, c0, h, w)
        return cls(g.x0, g.y0, g.cell, g.width, g.height, g.crs, grid.x0, grid.y0, int(r0), int(c0))

    def rowcol(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Fractional (row, col) in the window of map points, cell centres at integers (parent's minus the offset)."""
        col = (np.asarray(x) - self.parent_x0) / self.cell - 0.5
        row = (self.parent_y0 - np.asarray(y)) / self.cell - 0.5
        return row - self.row0, col - self.col0

    def xy(self, row: np.ndarray, col: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Map coordinates of the centres of window cells ``(row, col)``, computed as the parent grid does."""
        x = self.parent_x0 + (np.asarray(col) + self.col0 + 0.5) * self.cell
        y = self.parent_y0 - (np.asarray(row) + self.row0 + 0.5) * self.cell
        return x, y


def owners(polygons: gpd.GeoDataFrame, grid: GridSpec, tiles: Iterable[Tile]) -> np.ndarray:
    """Name of the tile that owns each polygon: the one whose cells hold its centroid.

    Parameters
    ----------
    polygons : GeoDataFrame
        Polygons on ``grid``.
    grid : GridSpec
        Stage grid the ``tiles`` partition.
    tiles : iterable of Tile
        Windows partitioning ``grid`` (:meth:`kitegully.terrain.tiling.TilingParams.tiles`).

    Returns
    -------
    ndarray of str
        One tile name per polygon.
    """
    tiles = list(tiles)
    out = np.empty(len(polygons), dtype=object)
    if not len(polygons):
        return out.astype(str)
    cen = polygons.geometry.centroid
    r, c = grid.index(cen.x.to_numpy(), cen.y.to_numpy())
    r = np.clip(r, 0, grid.height - 1)
    c = np.clip(c, 0, grid.width - 1)
    for t in tiles:
        inside = (r >= t.r0) & (r < t.r0 + t.h) & (c >= t.c0) & (c < t.c0 + t.w)
        out[inside] = t.name
    return out.astype(str)


def margin_cells(params: PolygonParams, cell: float) -> int:
    """Cells a tile's window extends beyond its polygons' bounding boxes.

    ``rim_search_m`` (section ends prolonged to the rim or, with ``no_rim: highest_ground``, to
    the highest ground within it) + ``bank_fit_m`` (the banks fitted beyond the ends, for the
    ``banks`` / ``bank_lines`` references) + ``ground_segment_m`` (ground profile drape
    prolonged at both ends; once more with ``ground_along_axis``, whose drapes are shifted that far
    along the axis) + one cell (bilinear drape), rounded up, plus 2 cells (the bounding box is
    taken one cell wide around the label).
    """
    bank = params.bank_fit_m if params.reference in ("banks", "bank_lines") else 0.0
    ground = params.ground_segment_m * (2 if params.ground_along_axis else 1)
    return int(ceil((params.rim_search_m + bank + ground + cell) / cell - 1e-9)) + 2


def polygons_window(polygons: gpd.GeoDataFrame, grid: GridSpec, margin: int) -> tuple[int, int, int, int] | None:
    """(row0, col0, rows, cols) of the union of the polygons' bounds plus ``margin`` cells, clipped to the grid.

    ``row0`` and ``col0`` are even (see the code).

    Parameters
    ----------
    polygons : GeoDataFrame
        Polygons on ``grid``.
    grid : GridSpec
        Stage grid.
    margin : int
        Cells added on every side.

    Returns
    -------
    tuple of int or None
        ``(row0, col0, rows, cols)``; None when there are no polygons.
    """
    if not len(polygons):
        return None
    x0, y0, x1, y1 = polygons.total_bounds
    c0 = int(np.floor((x0 - grid.x0) / grid.cell)) - margin
    c1 = int(np.ceil((x1 - grid.x0) / grid.cell)) + margin
    r0 = int(np.floor((grid.y0 - y1) / grid.cell)) - margin
    r1 = int(np.ceil((grid.y0 - y0) / grid.cell)) + margin
    # even offsets: numpy rounds halves to even, so a sample exactly between two cells (the rim
    # search rounds positions to cells) goes to the same cell in the window as in the grid
    r0, c0 = max(r0 - r0 % 2, 0), max(c0 - c0 % 2, 0)
    r1, c1 = min(r1, grid.height), min(c1, grid.width)
    return r0, c0, r1 - r0, c1 - c0


def read_window(path: str | Path, r0: int, c0: int, h: int, w: int) -> np.ndarray:
    """One window of band 1 of a raster (inside the raster; float nodata as NaN).

    Parameters
    ----------
    path : str or Path
        The raster.
    r0, c0 : int
        Top-left cell of the window.
    h, w : int
        Rows and columns of the window.

    Returns
    -------
    ndarray (h, w)
        The window's values in the raster's type.
    """
    import rasterio
    from rasterio.windows import Window

    with rasterio.open(path) as src:
        a = src.read(1, window=Window(c0, r0, w, h))
        if a.dtype.kind == "f" and src.nodata is not None and not np.isnan(src.nodata):
            a = np.where(a == src.nodata, np.nan, a)
    return a


def measure_tile(polygons: gpd.GeoDataFrame, grid: GridSpec, tile: Tile, read: Callable[[str, int, int, int, int], np.ndarray],
                 params: PolygonParams, tiles: Iterable[Tile]) -> tuple[gpd.GeoDataFrame, gpd.GeoDataFrame, pd.DataFrame]:
    """Medial axes, sections and morphometry of the polygons that ``tile`` owns.

    Parameters
    ----------
    polygons : GeoDataFrame
        All polygons at the morphometry threshold (``polygon_id`` = their label).
    grid : GridSpec
        Stage grid.
    tile : Tile
        This job's tile.
    read : callable
        ``read(name, r0, c0, h, w)`` -> the window of raster ``name`` (one of
        :data:`WINDOW_RASTERS`: the labels at the morphometry threshold, the stage DEM, the
        pool level and the rim band).
    params : PolygonParams
    tiles : iterable of Tile
        All tiles (ownership is decided among them).

    Returns
    -------
    axes, sections, morphometry
        As :func:`kitegully.polygons.stage.measure_morphometry`, for the owned polygons only.

    Notes
    -----
    Memory O(window cells); time O(Σ owned polygons' work), as the whole-grid step.
    """
    own = polygons[owners(polygons, grid, tiles) == tile.name]
    win = polygons_window(own, grid, margin_cells(params, grid.cell))
    if win is None:
        log.info("tile %s owns no polygon", tile.name)
        return measure_morphometry(np.zeros((1, 1), np.int32), own, np.zeros((1, 1)), np.zeros((1, 1)), np.zeros((1, 1), bool),
                                   grid, params)
    r0, c0, h, w = win
    a = {k: read(k, r0, c0, h, w) for k in WINDOW_RASTERS}
    log.info("tile %s: %d polygons, window rows %d+%d, cols %d+%d", tile.name, len(own), r0, h, c0, w)
    return measure_morphometry(a["labels"].astype(np.int32), own, a["dem"], a["level"], a["rims"].astype(bool),
                               WindowGrid.of(grid, r0, c0, h, w), params)


def merge_morphometry(parts: Iterable[tuple[gpd.GeoDataFrame, gpd.GeoDataFrame, pd.DataFrame]], crs: str
                      ) -> tuple[gpd.GeoDataFrame, gpd.GeoDataFrame, pd.DataFrame]:
    """Join the tiles' (axes, sections, morphometry) in polygon order (stable: a polygon's rows keep theirs)."""
    parts = list(parts)
    out = []
    for k in range(3):
        frames = [p[k] for p in parts if len(p[k])]
        if not frames:
            out.append(parts[0][k].iloc[:0] if parts else pd.DataFrame())
            continue
        df = pd.concat(frames, ignore_index=True).sort_values("polygon_id", kind="mergesort", ignore_index=True)
        out.append(gpd.GeoDataFrame(df, geometry="geometry", crs=crs) if k < 2 else df)
    return out[0], out[1], out[2]


def merged_summary(summary_map: pd.DataFrame, axes: gpd.GeoDataFrame, sections: gpd.GeoDataFrame, morph: pd.DataFrame,
                   params: PolygonParams, tile_seconds: float, n_tiles: int) -> pd.DataFrame:
    """The stage summary of a tiled site: ``polygons_map``'s rows, the morphometry rows, then the times.

    Parameters
    ----------
    summary_map : DataFrame
        ``polygons_map``'s summary (``quantity, value``); its ``time morphometry (s)`` row is dropped.
    axes : GeoDataFrame
        Merged medial axes.
    sections : GeoDataFrame
        Merged cross-sections.
    morph : DataFrame
        Merged per-polygon morphometry.
    params : PolygonParams
        Method parameters.
    tile_seconds : float
        Time of the tile jobs (s).
    n_tiles : int
        Number of tile jobs.

    Returns
    -------
    DataFrame
        ``quantity, value`` with the values as str.
    """
    is_time = summary_map["quantity"].str.startswith("time ")
    timing = summary_map[is_time & (summary_map["quantity"] != "time morphometry (s)")]
    rows = list(summary_map[~is_time].itertuples(index=False, name=None)) + morphometry_rows(axes, sections, morph, params)
    rows += list(timing.itertuples(index=False, name=None))
    rows.append((f"time morphometry, {n_tiles} tile jobs (s)", round(tile_seconds, 2)))
    return pd.DataFrame(rows, columns=["quantity", "value"]).astype({"value": str})
