"""Trimmed-mean gridding of dense points to a 2 cm DEM and orthophoto (Mayr et al. 2016).

001 sect. 2.2: "3D point clouds were aggregated to a raster DEM (cell size 2 cm), using
the 25 % trimmed mean of the points' z-values in each raster cell (to discard
outliers)".  [I] (METHODS 2.2, ambiguity 2.5): a trim of 25 % drops the lowest
``k = floor(0.25 n)`` and the highest ``k`` z values of a cell's ``n`` points and averages
the rest, the convention of ``scipy.stats.trim_mean``; a cell with 1–3 points keeps them all.
The orthophoto colour of a cell is the mean colour of the same kept points, so DEM and
orthophoto describe one surface.

The paper cut the periphery by hand; here the cells outside the ring of camera
positions (convex hull, or the circle fitted to them) are set to nodata
(:func:`periphery_mask`): matching quality drops where the views become grazing and the
overlap thin, which is outside the walked circle.

Cost: O(N log N) for N points (one lexsort), then O(N) vectorised numpy; memory O(N).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from matplotlib.path import Path as MplPath
from scipy import ndimage
from scipy.spatial import ConvexHull

from kitegully import InputError
from kitegully.io.raster import GridSpec


@dataclass(frozen=True)
class GriddedSurface:
    """DEM, orthophoto and point counts on one grid.

    Attributes
    ----------
    grid : GridSpec
    dem : numpy.ndarray
        float32 (rows, cols), trimmed-mean z (m); NaN where no points or cropped.
    ortho : numpy.ndarray or None
        uint8 (bands, rows, cols) mean colour of the kept points; 0 where ``dem`` is NaN.
    count : numpy.ndarray
        int32 (rows, cols) points that fell in each cell (before trimming).
    """

    grid: GridSpec
    dem: np.ndarray
    ortho: np.ndarray | None
    count: np.ndarray


def trimmed_cell_means(
    cell_index: np.ndarray, z: np.ndarray, n_cells: int, trim: float = 0.25, extra: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Per-cell trimmed mean of ``z``; optionally the mean of ``extra`` over the same kept points.

    Parameters
    ----------
    cell_index
        (N,) int, flat cell index of each point in ``[0, n_cells)``.
    z
        (N,) values to trim and average.
    n_cells
        Number of cells.
    trim
        Share cut from *each* tail, ``0 <= trim < 0.5``: ``floor(trim·n)`` lowest and as many
        highest values are dropped (``scipy.stats.trim_mean``).
    extra
        Optional (N, B) values (e.g. colours) averaged over the points kept for ``z``.

    Returns
    -------
    mean : (n_cells,) float64, NaN in empty cells
    count : (n_cells,) int64 points per cell before trimming
    extra_mean : (n_cells, B) float64 or None
    """
    if not 0.0 <= trim < 0.5:
        raise InputError(f"trim: {trim} is not in [0, 0.5) (share cut from each tail)")
    cell_index = np.asarray(cell_index, dtype=np.int64)
    z = np.asarray(z, dtype=np.float64)
    order = np.lexsort((z, cell_index))  # by cell, then by z inside the cell
    cs = cell_index[order]
    count = np.bincount(cs, minlength=n_cells)
    start = np.concatenate(([0], np.cumsum(count)[:-1]))
    rank = np.arange(len(cs)) - start[cs]
    k = np.floor(trim * count + 1e-9).astype(np.int64)  # guard 0.25*4 = 0.9999…
    keep = (rank >= k[cs]) & (rank < count[cs] - k[cs])
    kept_cells = cs[keep]
    n_kept = np.bincount(kept_cells, minlength=n_cells)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.bincount(kept_cells, weights=z[order][keep], minlength=n_cells) / n_kept
        extra_mean = None
        if extra is not None:
            ex = np.asarray(extra, dtype=np.float64).reshape(len(z), -1)[order][keep]
            extra_mean = np.column_stack(
                [np.bincount(kept_cells, weights=ex[:, b], minlength=n_cells) / n_kept for b in range(ex.shape[1])]
            )
    return mean, count, extra_mean


def periphery_mask(grid: GridSpec, camera_xy: np.ndarray, shape: str = "hull") -> np.ndarray:
    """Cells inside the ring of camera positions (True = keep).

    Parameters
    ----------
    grid
        Output grid.
    camera_xy
        (M, 2) camera centres (map x, y), M >= 3.
    shape
        ``"hull"``: convex hull of the camera positions; ``"circle"``: the least-squares
        circle through them (algebraic Kåsa fit), for a walk that is roughly a circle.

    Returns
    -------
    (rows, cols) bool
    """
    P = np.asarray(camera_xy, dtype=float)[:, :2]
    if len(P) < 3:
        raise InputError(f"camera positions: {len(P)} given, at least 3 are needed to crop by the camera circle")
    xs, ys = grid.cell_centres()
    X, Y = np.meshgrid(xs, ys)
    if shape == "circle":
        A = np.column_stack([P[:, 0], P[:, 1], np.ones(len(P))])
        b = (P ** 2).sum(axis=1)
        sol = np.linalg.lstsq(A, b, rcond=None)[0]
        cx, cy = sol[0] / 2, sol[1] / 2
        r = np.sqrt(sol[2] + cx * cx + cy * cy)
        return (X - cx) ** 2 + (Y - cy) ** 2 <= r * r
    if shape != "hull":
        raise InputError(f"periphery shape: '{shape}' is not one of hull, circle")
    hull = ConvexHull(P)
    path = MplPath(P[hull.vertices])
    return path.contains_points(np.column_stack([X.ravel(), Y.ravel()])).reshape(X.shape)


def grid_points(
    xyz: np.ndarray,
    grid: GridSpec,
    colours: np.ndarray | None = None,
    trim: float = 0.25,
    camera_xy: np.ndarray | None = None,
    periphery: str = "hull",
) -> GriddedSurface:
    """Grid dense points to a trimmed-mean DEM and a mean-colour orthophoto.

    Parameters
    ----------
    xyz
        (N, 3) points in the grid's CRS (m).
    grid
        Output grid (2 cm in 001).
    colours
        Optional (N, B) uint8 point colours.
    trim
        Share cut from each tail of a cell's z values ([P] 25 %, [I] per tail).
    camera_xy
        Optional (M, 2) camera centres: cells outside their ring become nodata.
    periphery
        ``"hull"`` or ``"circle"`` (see :func:`periphery_mask`).

    Returns
    -------
    GriddedSurface
    """
    xyz = np.asarray(xyz, dtype=np.float64)
    if xyz.ndim != 2 or xyz.shape[1] != 3:
        raise InputError(f"points: expected an (N, 3) array, got shape {xyz.shape}")
    row, col = grid.rowcol(xyz[:, 0], xyz[:, 1])
    r = np.floor(row + 0.5).astype(np.int64)
    c = np.floor(col + 0.5).astype(np.int64)
    inside = (r >= 0) & (r < grid.height) & (c >= 0) & (c < grid.width) & np.isfinite(xyz[:, 2])
    idx = r[inside] * grid.width + c[inside]
    ex = None if colours is None else np.asarray(colours)[inside]
    mean, count, col_mean = trimmed_cell_means(idx, xyz[inside, 2], grid.width * grid.height, trim, ex)
    shape = (grid.height, grid.width)
    dem = mean.reshape(shape).astype(np.float32)
    if camera_xy is not None:
        dem[~periphery_mask(grid, camera_xy, periphery)] = np.nan
    ortho = None
    if col_mean is not None:
        ortho = np.rint(np.nan_to_num(col_mean)).clip(0, 255).astype(np.uint8).T.reshape(-1, *shape)
        ortho[:, np.isnan(dem)] = 0
    return GriddedSurface(grid, dem, ortho, count.reshape(shape).astype(np.int32))


def fill_holes(dem: np.ndarray, ortho: np.ndarray, inside: np.ndarray, max_cells: int) -> tuple[np.ndarray, np.ndarray, int]:
    """Fill nodata holes inside the crop up to ``max_cells`` from their rim; return the count filled."""
    holes = ~np.isfinite(dem) & inside
    lab, n = ndimage.label(holes)
    if n == 0:
        return dem, ortho, 0
    sizes = np.bincount(lab.ravel())
    small = (sizes <= max_cells)
    small[0] = False
    fill = small[lab]
    if not fill.any():
        return dem, ortho, 0
    known = np.isfinite(dem)
    idx = ndimage.distance_transform_edt(~known, return_distances=False, return_indices=True)
    dem2 = dem.copy()
    dem2[fill] = dem[tuple(i[fill] for i in idx)]
    mask = fill.astype(np.uint8)
    img = np.ascontiguousarray(np.moveaxis(ortho, 0, -1))
    img = cv2.inpaint(img, mask, 3, cv2.INPAINT_TELEA)
    ortho2 = ortho.copy()
    ortho2[:, fill] = np.moveaxis(img, -1, 0)[:, fill]
    return dem2, ortho2, int(fill.sum())


def near_median_surface(xyz: np.ndarray, grid: GridSpec, cell_m: float, tolerance_m: float) -> np.ndarray:
    """Points within ``tolerance_m`` of the per-cell median height on a coarse grid (mismatches, sky, the far hillside)."""
    k = max(1, int(round(cell_m / grid.cell)))
    w, h = -(-grid.width // k), -(-grid.height // k)
    col = np.floor((xyz[:, 0] - grid.x0) / (grid.cell * k)).astype(np.int64)
    row = np.floor((grid.y0 - xyz[:, 1]) / (grid.cell * k)).astype(np.int64)
    inside = (row >= 0) & (row < h) & (col >= 0) & (col < w)
    idx = np.where(inside, row * w + col, 0)
    med, _, _ = trimmed_cell_means(idx[inside], xyz[inside, 2], w * h, 0.45)
    dev = np.full(len(xyz), np.inf)
    dev[inside] = np.abs(xyz[inside, 2] - med[idx[inside]])
    return dev <= tolerance_m
