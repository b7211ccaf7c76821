"""Tile grids of large sites as Snakemake jobs (issue 21): names, windows, merge of products.

A site that sets ``tiling:`` runs the work that grows with its area as one job per tile
plus one merge job per product. The tile *names* are a pure function of the config (the
site extent and ``tiling.tile_m``), so the workflow expands its ``{tile}`` wildcard when
it builds the DAG, without a checkpoint; the tile *windows* (rows and columns) split the
raster each job reads into the same number of near-equal parts, so they always partition
that raster exactly, whatever rounding made its shape.

Tiles of one product are disjoint; each job reads its window plus the overlap (halo) its
method needs (one cell for :mod:`kitegully.terrain.tiled_fill`, the kernel radius for a
smoothing), and a merge rule writes the mosaic window by window (memory O(tile)).
"""

from __future__ import annotations

from dataclasses import dataclass
from math import ceil
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping

import numpy as np

from kitegully import InputError
from kitegully.config import config_section
from kitegully.terrain.tiled_fill import Tile


@dataclass(frozen=True)
class TilingParams:
    """Tiling of a large site (config section ``tiling``).

    Attributes
    ----------
    tile_m : float
        Target tile side (m). [I] The number of tiles along each axis is
        ``ceil(extent / tile_m)``; a tile of 500 m at 0.2 m is 2500² = 6.25 M cells, about
        75 MB for the per-tile fill (float64 fill, int32 labels, queues), so a tile job
        stays far below 1 GB while a 3.18 km² site gives 4 × 4 = 16 jobs per tiled step,
        enough to keep 2 cores or a small cluster busy.
    width_m, height_m : float
        Extent of the site (m) the tile counts follow from: the twin's ``twin.extent`` or,
        for a real site, ``tiling.extent``.
    """

    tile_m: float
    width_m: float
    height_m: float

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any]) -> "TilingParams":
        """From the whole site config (``tiling`` plus ``twin.extent`` when the extent is null)."""
        t = cfg.get("tiling")
        if not t:
            raise InputError("tiling: the site has no tiling section")
        config_section(t, "tiling", ("tile_m", "extent"))
        ext = t.get("extent") or (cfg.get("twin") or {}).get("extent")
        if not ext:
            raise InputError("tiling.extent: a site that is not a twin must give the extent (width_m, height_m) to tile")
        tile_m = float(t["tile_m"])
        if tile_m <= 0:
            raise InputError(f"tiling.tile_m: must be > 0, got {tile_m}")
        return cls(tile_m, float(ext["width_m"]), float(ext["height_m"]))

    @property
    def counts(self) -> tuple[int, int]:
        """Tiles along the rows (north-south) and the columns (west-east)."""
        return max(1, ceil(self.height_m / self.tile_m - 1e-9)), max(1, ceil(self.width_m / self.tile_m - 1e-9))

    def names(self) -> list[str]:
        """Wildcard values of all tiles, row-major (``r000_c000``, ``r000_c001``, ...)."""
        nr, nc = self.counts
        return [Tile(0, i, j, 0, 0, 0, 0).name for i in range(nr) for j in range(nc)]

    def tiles(self, shape: tuple[int, int]) -> list[Tile]:
        """The windows of all tiles on a raster of ``shape`` (rows, cols)."""
        return split_grid(shape, *self.counts)

    def tile(self, shape: tuple[int, int], name: str) -> Tile:
        """The window of the tile called ``name`` on a raster of ``shape``."""
        for t in self.tiles(shape):
            if t.name == name:
                return t
        raise InputError(f"tile {name}: not in the {self.counts[0]} x {self.counts[1]} grid of tiling.tile_m {self.tile_m}")


def split_grid(shape: tuple[int, int], n_rows: int, n_cols: int) -> list[Tile]:
    """Cut ``shape`` cells into ``n_rows`` × ``n_cols`` near-equal tiles (row-major ids).

    Tile ``(i, j)`` covers rows ``floor(i H / n_rows) .. floor((i+1) H / n_rows)`` and the
    same for columns, so the tiles partition the grid exactly. Raises ``ValueError`` when
    a tile would be empty (more tiles than cells).

    Parameters
    ----------
    shape : tuple of int
        Grid shape ``(H, W)`` (cells).
    n_rows, n_cols : int
        Number of tiles along the rows and the columns.

    Returns
    -------
    list of Tile
        The tiles in row-major order.
    """

    h, w = int(shape[0]), int(shape[1])
    if n_rows < 1 or n_cols < 1 or n_rows > h or n_cols > w:
        raise ValueError(f"cannot split a {h} x {w} grid into {n_rows} x {n_cols} tiles")
    rb = [i * h // n_rows for i in range(n_rows + 1)]
    cb = [j * w // n_cols for j in range(n_cols + 1)]
    return [Tile(i * n_cols + j, i, j, rb[i], cb[j], rb[i + 1] - rb[i], cb[j + 1] - cb[j])
            for i in range(n_rows) for j in range(n_cols)]


def whole_block_tiles(shape: tuple[int, int], block: int, tiling: "TilingParams", product: str, source: str,
                      block_key: str, block_text: str) -> list[Tile]:
    """Tiles of a raster of ``shape`` made of whole processing blocks of ``block`` cells.

    The ``ceil(H/block) x ceil(W/block)`` blocks are split into the tiling's ``n_rows x n_cols``
    near-equal rectangles (:func:`split_grid`), so a tile job processes exactly the blocks the
    untiled job would; the last blocks may be cut by the raster's edge.

    Parameters
    ----------
    shape : (rows, cols) of the raster.
    block : side of a processing block (cells).
    tiling : the site's tiling.
    product, source, block_key, block_text : words of the refusal, e.g. ``"kite-map"``, ``"the
        orthophoto"``, ``"obia.kite_scale.tile_cells"``, ``"obia.kite_scale.tile_cells 2048"``.

    Returns
    -------
    list of Tile in row-major order (names as :meth:`TilingParams.names`).

    Raises
    ------
    InputError
        More tiles along an axis than blocks.
    """
    h, w = int(shape[0]), int(shape[1])
    nbr, nbc = ceil(h / block), ceil(w / block)
    nr, nc = tiling.counts
    if nr > nbr or nc > nbc:
        raise InputError(f"tiling.tile_m: {tiling.tile_m:g} m gives {nr} x {nc} {product} tiles but {source} has only "
                         f"{nbr} x {nbc} blocks of {block_text}; raise tiling.tile_m or lower {block_key}")
    out = []
    for b in split_grid((nbr, nbc), nr, nc):
        r0, c0 = b.r0 * block, b.c0 * block
        out.append(Tile(b.tid, b.ti, b.tj, r0, c0, min((b.r0 + b.h) * block, h) - r0, min((b.c0 + b.w) * block, w) - c0))
    return out


def write_mosaic(path: str | Path, like: str | Path, tiles: Iterable[Tile], part: Callable[[Tile], np.ndarray],
                 dtype: str | None = None) -> None:
    """Write a raster on the grid of ``like`` window by window: ``part(tile)`` gives each tile's cells.

    Parameters
    ----------
    path : path
        Output GeoTIFF (tiled, DEFLATE; a plain GeoTIFF, not a COG, so that it streams).
    like : path
        Raster whose grid (transform, CRS, shape) the mosaic takes.
    tiles : iterable of Tile
        Windows that partition the grid (e.g. :meth:`TilingParams.tiles`).
    part : callable
        ``part(tile) -> ndarray (tile.h, tile.w)``.
    dtype : str, optional
        Output data type (default that of ``like``). Float rasters get NaN nodata.

    Notes
    -----
    Memory O(largest tile); time O(cells).
    """
    import rasterio
    from rasterio.windows import Window

    from kitegully.io.raster import _profile, grid_of

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with rasterio.open(like) as src:
        grid = grid_of(src, like)
        dtype = dtype or src.dtypes[0]
    nodata = float("nan") if np.dtype(dtype).kind == "f" else None
    with rasterio.open(path, "w", **_profile(grid, 1, dtype, nodata)) as dst:
        for t in tiles:
            a = np.asarray(part(t))
            if a.shape != (t.h, t.w):
                raise ValueError(f"tile {t.name}: part has shape {a.shape}, window {(t.h, t.w)}")
            dst.write(a.astype(dtype, copy=False), 1, window=Window(t.c0, t.r0, t.w, t.h))
