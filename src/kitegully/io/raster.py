"""GeoTIFF reading and writing with the project's conventions.

Elevation rasters are float32 with NaN as nodata; every raster is tiled (256×256)
and DEFLATE-compressed, in the site's projected CRS. Products are written as
Cloud-Optimised GeoTIFF (GDAL's COG driver: tiled, compressed, internal overviews,
image data after the header and overviews) so that QGIS, GDAL, web viewers and cloud
readers open them fast at any zoom; a raster whose cells can be legitimately 0 in every
band (an orthophoto) carries an internal mask band instead of a nodata value.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import numpy as np
import rasterio
import rasterio.shutil
from affine import Affine
from rasterio.crs import CRS
from rasterio.io import MemoryFile
from rasterio.windows import Window

from kitegully import InputError


@dataclass(frozen=True)
class GridSpec:
    """A north-up grid: origin at the top-left corner of the top-left cell.

    Attributes
    ----------
    x0, y0 : float
        Map coordinates of the top-left corner (m).
    cell : float
        Cell size (m); rows go south, columns go east.
    width, height : int
        Number of columns and rows.
    crs : str
        CRS understood by rasterio (e.g. ``"EPSG:32632"``).
    """

    x0: float
    y0: float
    cell: float
    width: int
    height: int
    crs: str

    @property
    def transform(self) -> Affine:
        """Affine transform from (col, row) to map coordinates, as rasterio uses it (north-up, origin top-left)."""
        return Affine(self.cell, 0.0, self.x0, 0.0, -self.cell, self.y0)

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """(xmin, ymin, xmax, ymax) in map units."""
        return (self.x0, self.y0 - self.height * self.cell, self.x0 + self.width * self.cell, self.y0)

    @classmethod
    def from_transform(cls, transform: Affine, width: int, height: int, crs: str) -> "GridSpec":
        """The grid of a north-up ``transform`` (as rasterio reports it); no checks here.

        Parameters
        ----------
        transform : Affine
            North-up transform; its ``a`` is taken as the cell size (m) and ``(c, f)`` as the origin.
        width, height : int
            Number of columns and rows.
        crs : str
            CRS understood by rasterio.

        Returns
        -------
        GridSpec
            The grid.
        """
        return cls(transform.c, transform.f, transform.a, width, height, crs)

    @classmethod
    def covering(cls, bounds: tuple[float, float, float, float], cell: float, crs: str) -> "GridSpec":
        """The smallest grid covering ``bounds = (xmin, ymin, xmax, ymax)`` whose origin
        is a whole multiple of ``cell`` (so it aligns with any such grid).

        Parameters
        ----------
        bounds : (float, float, float, float)
            ``(xmin, ymin, xmax, ymax)`` to cover (m).
        cell : float
            Cell size (m).
        crs : str
            CRS understood by rasterio.

        Returns
        -------
        GridSpec
            The covering grid.
        """
        xmin, ymin, xmax, ymax = bounds
        x0 = np.floor(xmin / cell) * cell
        y0 = np.ceil(ymax / cell) * cell
        w = int(np.ceil((xmax - x0) / cell))
        h = int(np.ceil((y0 - ymin) / cell))
        return cls(float(x0), float(y0), cell, w, h, crs)

    @property
    def shape(self) -> tuple[int, int]:
        """(rows, cols)."""
        return (self.height, self.width)

    def cell_centres(self, row0: int = 0, col0: int = 0, nrows: int | None = None,
                     ncols: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """1-D arrays of column-centre x and row-centre y coordinates.

        By default the whole grid; ``row0, col0, nrows, ncols`` select a block of rows
        and columns of this grid's lattice, which may extend outside it (negative
        ``row0``/``col0`` or beyond the last row/column), e.g. a tile with a margin.

        Parameters
        ----------
        row0, col0 : int
            First row and column of the block.
        nrows, ncols : int or None
            Number of rows and columns; None = up to the last row or column of the grid.

        Returns
        -------
        xs : ndarray (ncols,)
            Column-centre x coordinates (m).
        ys : ndarray (nrows,)
            Row-centre y coordinates (m), north to south.
        """
        nrows = self.height - row0 if nrows is None else nrows
        ncols = self.width - col0 if ncols is None else ncols
        xs = self.x0 + (col0 + np.arange(ncols) + 0.5) * self.cell
        ys = self.y0 - (row0 + np.arange(nrows) + 0.5) * self.cell
        return xs, ys

    def xy(self, row: np.ndarray, col: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Map coordinates of the centres of cells ``(row, col)`` (integer or fractional)."""
        x = self.x0 + (np.asarray(col) + 0.5) * self.cell
        y = self.y0 - (np.asarray(row) + 0.5) * self.cell
        return x, y

    @property
    def centre(self) -> tuple[float, float]:
        """Map coordinates of the centre of the grid's extent."""
        return self.x0 + self.width * self.cell / 2, self.y0 - self.height * self.cell / 2

    def unravel(self, flat_index: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Integer (row, col) of flat (row-major) cell indices."""
        flat_index = np.asarray(flat_index)
        r = flat_index // self.width
        return r, flat_index - r * self.width

    def flat_xy(self, flat_index: np.ndarray) -> np.ndarray:
        """(N, 2) map coordinates of the centres of cells given by flat (row-major) index."""
        x, y = self.xy(*self.unravel(flat_index))
        return np.column_stack([x, y])

    def rowcol(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Fractional (row, col) of map points, cell centres at integers."""
        col = (np.asarray(x) - self.x0) / self.cell - 0.5
        row = (self.y0 - np.asarray(y)) / self.cell - 0.5
        return row, col

    def index(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Integer (row, col) of the cells containing map points (may lie outside the grid).

        A point on a cell's west or north edge belongs to that cell.
        """
        col = np.floor((np.asarray(x, dtype=np.float64) - self.x0) / self.cell).astype(np.int64)
        row = np.floor((self.y0 - np.asarray(y, dtype=np.float64)) / self.cell).astype(np.int64)
        return row, col

    def contains(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Whether map points fall inside the grid (its cells, edges by :meth:`index`)."""
        row, col = self.index(x, y)
        return (row >= 0) & (col >= 0) & (row < self.height) & (col < self.width)

    def window(self, row0: int, col0: int, nrows: int, ncols: int) -> "GridSpec":
        """The grid of a block of rows and columns (may extend outside this grid).

        Parameters
        ----------
        row0, col0 : int
            First row and column of the block in this grid.
        nrows, ncols : int
            Number of rows and columns of the block.

        Returns
        -------
        GridSpec
            The block's grid, same cell size and CRS.
        """
        return GridSpec(self.x0 + col0 * self.cell, self.y0 - row0 * self.cell, self.cell, ncols, nrows, self.crs)

    def refined(self, factor: int) -> "GridSpec":
        """Same extent with each cell split into ``factor × factor`` cells."""
        return GridSpec(self.x0, self.y0, self.cell / factor, self.width * factor, self.height * factor, self.crs)

    def coarsened(self, factor: int) -> "GridSpec":
        """Cells of ``factor × factor`` cells from the top-left corner (partial ones dropped)."""
        return GridSpec(self.x0, self.y0, self.cell * factor, self.width // factor, self.height // factor, self.crs)

    def shifted(self, dx: float, dy: float) -> "GridSpec":
        """The same grid with its origin moved by ``(dx, dy)`` (e.g. into a local frame)."""
        return GridSpec(self.x0 + dx, self.y0 + dy, self.cell, self.width, self.height, self.crs)

    def resampled(self, cell: float, cover: bool = False) -> "GridSpec":
        """Same origin on a different cell size; the extent is rounded down to whole cells,
        or up with ``cover=True`` (the new grid then covers this one)."""
        rnd = np.ceil if cover else np.floor
        w = int(rnd(self.width * self.cell / cell))
        h = int(rnd(self.height * self.cell / cell))
        return GridSpec(self.x0, self.y0, cell, w, h, self.crs)


@dataclass
class Raster:
    """An array that knows its grid: data, north-up grid (transform + CRS) and nodata.

    What :meth:`read` returns and :meth:`write` takes, like xDEM's ``DEM``. Float rasters
    carry NaN for nodata in memory (``nodata`` is then ``nan``); integer rasters keep
    their sentinel in ``nodata``. Nodata is decided once, here, and never re-derived.

    Attributes
    ----------
    data : numpy.ndarray
        2-D ``(rows, cols)`` or bands-first 3-D ``(bands, rows, cols)`` array.
    grid : GridSpec
        Cell size, origin, shape and CRS.
    nodata : float, int or None
        Nodata value of integer rasters; NaN for float rasters.
    """

    data: np.ndarray
    grid: GridSpec
    nodata: float | int | None = None

    def __post_init__(self) -> None:
        if self.data.shape[-2:] != (self.grid.height, self.grid.width):
            raise ValueError(f"array shape {self.data.shape[-2:]} does not match grid {(self.grid.height, self.grid.width)}")
        if self.nodata is None and self.data.dtype.kind == "f":
            self.nodata = float("nan")

    @classmethod
    def read(cls, path: str | Path, band: int | None = 1) -> "Raster":
        """Read one band (or all with ``band=None``); see :func:`read_raster` for the checks."""
        data, grid, nodata = _read(path, band)
        return cls(data, grid, nodata)

    def write(self, path: str | Path, band_names: list[str] | None = None, tags: dict[str, str] | None = None,
              mask: np.ndarray | None = None) -> None:
        """Write as a Cloud-Optimised GeoTIFF (see :func:`write_raster`).

        Parameters
        ----------
        path : str or Path
            Output file (parent folders are created).
        band_names : list of str or None
            Band descriptions.
        tags : dict of str to str or None
            Dataset metadata.
        mask : ndarray (H, W) bool or None
            True where the cell has data; written as the internal mask band.
        """
        write_raster(path, self.data, self.grid, nodata=self.nodata, band_names=band_names, tags=tags, mask=mask)

    @property
    def transform(self) -> Affine:
        """Affine transform of the raster's grid."""
        return self.grid.transform

    @property
    def crs(self) -> str:
        """CRS of the raster's grid."""
        return self.grid.crs

    @property
    def cell(self) -> float:
        """Cell size of the raster's grid (m)."""
        return self.grid.cell

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """(xmin, ymin, xmax, ymax) in map units."""
        return self.grid.bounds

    @property
    def valid(self) -> np.ndarray:
        """Boolean mask of cells with data (all bands valid for a 3-D raster)."""
        if self.nodata is None:
            ok = np.ones(self.data.shape, bool)
        elif isinstance(self.nodata, float) and np.isnan(self.nodata):
            ok = np.isfinite(self.data)
        else:
            ok = self.data != self.nodata
        return ok.all(axis=0) if ok.ndim == 3 else ok

    def with_data(self, data: np.ndarray, nodata: float | int | None = None) -> "Raster":
        """A raster on the same grid holding ``data``."""
        return Raster(data, self.grid, nodata)


def _profile(grid: GridSpec, count: int, dtype: str, nodata, cog: bool = False) -> dict:
    """Creation profile: a tiled, compressed GeoTIFF, or with ``cog=True`` a COG.

    The plain GTiff profile allows streaming windowed writes of rasters larger than
    memory (twin truth rasters); the COG profile is for products (GDAL's COG driver is
    copy-only, so rasterio buffers the whole raster in memory and copies it on close).
    """
    if cog:
        return dict(
            driver="COG", width=grid.width, height=grid.height, count=count, dtype=dtype,
            crs=CRS.from_user_input(grid.crs), transform=grid.transform, nodata=nodata,
            compress="deflate", predictor="yes" if np.dtype(dtype).itemsize > 1 or np.dtype(dtype).kind == "f" else "no",
            blocksize=256, overviews="auto", bigtiff="IF_SAFER",
            # overviews of continuous fields average; class and id rasters keep their codes
            overview_resampling="average" if np.dtype(dtype).kind == "f" else "nearest",
        )
    tiled = grid.width >= 256 and grid.height >= 256
    profile = dict(
        driver="GTiff",
        width=grid.width,
        height=grid.height,
        count=count,
        dtype=dtype,
        crs=CRS.from_user_input(grid.crs),
        transform=grid.transform,
        compress="deflate",
        nodata=nodata,
        BIGTIFF="IF_SAFER",
    )
    if tiled:
        profile.update(tiled=True, blockxsize=256, blockysize=256)
    if np.dtype(dtype).kind == "f":
        profile["predictor"] = 3
    elif np.dtype(dtype).itemsize > 1:
        profile["predictor"] = 2
    return profile


def write_raster(
    path: str | Path,
    data: np.ndarray,
    grid: GridSpec,
    nodata: float | int | None = None,
    band_names: list[str] | None = None,
    tags: dict[str, str] | None = None,
    mask: np.ndarray | None = None,
    overview_resampling: str | None = None,
) -> None:
    """Write a 2-D (one band) or 3-D (bands first) array as a Cloud-Optimised GeoTIFF.

    Parameters
    ----------
    path
        Output file (parent folders are created).
    data
        ``(rows, cols)`` or ``(bands, rows, cols)`` array; written unchanged.
    grid
        Its grid; the shape must match.
    nodata
        Nodata value; float arrays get NaN unless given. Leave ``None`` with ``mask``.
    band_names, tags
        Band descriptions and dataset metadata.
    mask
        Optional ``(rows, cols)`` boolean array, True where the cell has data; written as
        the file's internal mask band (per-dataset, GDAL ``GDAL_TIFF_INTERNAL_MASK``), which
        QGIS and GDAL show as transparent. Use it instead of a nodata value for rasters
        whose valid cells may take any value (an orthophoto).
    overview_resampling
        GDAL resampling of the internal overviews; default ``average`` for float and
        ``nearest`` for integer rasters (class codes stay codes).

    Written with GDAL's COG driver (one CreateCopy of an in-memory dataset: tiles of
    256 × 256, DEFLATE with the matching predictor, overviews halving down to one tile).
    Cost: O(cells) time and one in-memory copy of the raster. Without ``mask`` the copy is
    made by :func:`rasterio.shutil.copy` from a GDAL MEM dataset, which releases Python's
    GIL while GDAL compresses (the same bytes as rasterio's COG writer, which holds it for
    the whole write): other threads, e.g. the gully stage's fill branch, keep running.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    arr = np.asarray(data)
    if arr.ndim == 2:
        arr = arr[None]
    if arr.shape[1:] != (grid.height, grid.width):
        raise ValueError(f"{path}: array shape {arr.shape[1:]} does not match grid {(grid.height, grid.width)}")
    if nodata is None and arr.dtype.kind == "f" and mask is None:
        nodata = float("nan")
    if mask is not None and np.shape(mask) != (grid.height, grid.width):
        raise ValueError(f"{path}: mask shape {np.shape(mask)} does not match grid {(grid.height, grid.width)}")
    profile = _profile(grid, arr.shape[0], arr.dtype.name, nodata, cog=True)
    if overview_resampling:
        profile["overview_resampling"] = overview_resampling
    if mask is None:
        keys = ("width", "height", "count", "dtype", "crs", "transform", "nodata")
        with MemoryFile() as mf, mf.open(driver="MEM", **{k: profile[k] for k in keys}) as mem:
            mem.write(arr)
            if band_names:
                mem.descriptions = tuple(band_names)
            if tags:
                mem.update_tags(**tags)
            opts = {k: v for k, v in profile.items() if k not in keys and k != "driver"}
            rasterio.shutil.copy(mem, path, driver="COG", **opts)
        return
    with rasterio.open(path, "w", **profile) as dst:
        dst.write(arr)
        if mask is not None:
            dst.write_mask(np.where(np.asarray(mask, bool), 255, 0).astype(np.uint8))
        if band_names:
            dst.descriptions = tuple(band_names)
        if tags:
            dst.update_tags(**tags)


def read_raster(path: str | Path, band: int | None = 1) -> tuple[np.ndarray, GridSpec]:
    """Read one band (or all bands with ``band=None``) and its grid.

    Nodata values of float rasters become NaN. Raises :class:`InputError` naming the
    file when it cannot be opened, is not north-up, or has no CRS.
    """
    data, grid, _ = _read(path, band)
    return data, grid


def read_grid(path: str | Path) -> GridSpec:
    """The grid of a raster file without reading its cells (the checks of :func:`read_raster`).

    Raises :class:`InputError` naming the file when it cannot be opened or its grid is not usable.
    """
    try:
        src = rasterio.open(Path(path))
    except rasterio.errors.RasterioIOError as exc:
        raise InputError(f"{path}: cannot open raster ({exc})") from None
    with src:
        return grid_of(src, path)


def grid_of(src: rasterio.DatasetReader, path: str | Path) -> GridSpec:
    """The grid of an open rasterio dataset ``src`` read from ``path``.

    Raises :class:`InputError` naming ``path`` when the raster is rotated or not
    north-up, has no CRS, or has non-square cells (the checks of every reader).
    """
    t = src.transform
    if t.b != 0 or t.d != 0 or t.e >= 0:
        raise InputError(f"{path}: raster is rotated or not north-up; reproject it first")
    if src.crs is None:
        raise InputError(f"{path}: raster has no CRS")
    if abs(abs(t.a) - abs(t.e)) > 1e-9 * abs(t.a):
        raise InputError(f"{path}: cells are not square ({t.a} x {-t.e})")
    return GridSpec.from_transform(t, src.width, src.height, src.crs.to_string())


def _read(path: str | Path, band: int | None) -> tuple[np.ndarray, GridSpec, float | int | None]:
    path = Path(path)
    try:
        src = rasterio.open(path)
    except rasterio.errors.RasterioIOError as exc:
        raise InputError(f"{path}: cannot open raster ({exc})") from None
    with src:
        grid = grid_of(src, path)
        data = src.read(band) if band is not None else src.read()
        nodata = src.nodata
        if data.dtype.kind == "f":
            if nodata is not None and not np.isnan(nodata):
                data = np.where(data == nodata, np.nan, data)
            nodata = float("nan")
    return data, grid, nodata


def iter_tiles(grid: GridSpec, tile: int, overlap: int) -> Iterator[tuple[Window, Window]]:
    """Yield (read window with overlap, core window) pairs covering the grid.

    The core windows tile the grid without gaps or overlap; each read window extends
    its core by ``overlap`` cells on every side, clipped to the grid.

    Parameters
    ----------
    grid : GridSpec
        The grid to tile.
    tile : int
        Side of a core window (cells); the last row and column of tiles may be smaller.
    overlap : int
        Margin added to each core window on every side (cells).

    Yields
    ------
    read : Window
        The core window with its margin, clipped to the grid.
    core : Window
        The core window.
    """
    for r0 in range(0, grid.height, tile):
        for c0 in range(0, grid.width, tile):
            h = min(tile, grid.height - r0)
            w = min(tile, grid.width - c0)
            rr0 = max(0, r0 - overlap)
            cc0 = max(0, c0 - overlap)
            rr1 = min(grid.height, r0 + h + overlap)
            cc1 = min(grid.width, c0 + w + overlap)
            yield Window(cc0, rr0, cc1 - cc0, rr1 - rr0), Window(c0, r0, w, h)
