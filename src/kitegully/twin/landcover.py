"""Land cover of the twin: field plots, tracks, tree rows, shrubs, buildings and water.

Plots are laid out in the valley frame ``(u, a)`` where ``a`` is the distance up the bank
from the edge of the valley floor: rows of fields parallel to the valley (roughly along
the contours), cut into plots along ``u``. Every property (row and plot boundaries,
class, tillage direction, tree positions) is a hash of integer indices and the seed, so
it can be evaluated cell by cell in any tile. Class codes are part of the twin's output
contract (``truth/landcover_classes.csv``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kitegully.twin.noise import fbm_grid, hash01
from kitegully.twin.terrain import Valley

CLASSES: dict[int, str] = {
    1: "bare_eroded",
    2: "ploughed",
    3: "grass",
    4: "shrub",
    5: "tree",
    6: "track",
    7: "building",
    8: "water",
    9: "gully",
}
CODE: dict[str, int] = {v: k for k, v in CLASSES.items()}
VEGETATION = ("grass", "shrub", "tree")


@dataclass(frozen=True)
class Fields:
    """Field layout parameters (m) and shares; see ``twin.fields`` in the config schema."""

    floor_margin: float
    row_depth: float
    row_jitter: float
    plot_length: float
    plot_jitter: float
    share_ploughed: float
    share_grass: float
    contour_share: float
    hump_height: float
    hump_width: float
    hump_clearance: float
    furrow_amplitude: float
    furrow_period: float
    seed: int

    @classmethod
    def from_config(cls, f: dict, seed: int) -> "Fields":
        """Build from the ``twin.fields`` section and the seed of the layout's jitter.

        The class shares are normalised to sum to 1; the row and plot jitters are capped at 0.45
        of the row depth and the plot length.
        """
        s = f["class_shares"]
        total = s["ploughed"] + s["grass"] + s["bare_eroded"]
        return cls(
            floor_margin=f["floor_margin_m"], row_depth=f["row_depth_m"], row_jitter=min(f["row_jitter_m"], 0.45 * f["row_depth_m"]),
            plot_length=f["plot_length_m"], plot_jitter=min(f["plot_jitter_m"], 0.45 * f["plot_length_m"]),
            share_ploughed=s["ploughed"] / total, share_grass=s["grass"] / total, contour_share=f["contour_tillage_share"],
            hump_height=f["hump_height_m"], hump_width=f["hump_width_m"], hump_clearance=f["hump_clearance_m"],
            furrow_amplitude=f["furrow_amplitude_m"], furrow_period=f["furrow_period_m"], seed=seed,
        )

    def row_boundary(self, bank: int | np.ndarray, k: int | np.ndarray) -> np.ndarray:
        """Distance up the bank of the boundary below row ``k`` (k = 0 is the floor edge)."""
        k = np.asarray(k)
        jit = self.row_jitter * (2.0 * hash01(bank, k, seed=self.seed + 11) - 1.0)
        return np.where(k <= 0, k * self.row_depth, k * self.row_depth + jit)

    def col_boundary(self, bank: np.ndarray, row: np.ndarray, j: np.ndarray) -> np.ndarray:
        """Distance along row ``row`` of the boundary before plot ``j`` (m), jittered per bank, row and plot.

        Parameters
        ----------
        bank : ndarray of int
            +1 right bank, −1 left bank, 0 valley floor.
        row : ndarray of int
            Row index.
        j : ndarray of int
            Plot index along the row.

        Returns
        -------
        ndarray
            Boundary position (m), broadcast over the arguments.
        """
        jit = self.plot_jitter * (2.0 * hash01(bank, row, j, seed=self.seed + 13) - 1.0)
        return np.asarray(j) * self.plot_length + jit

    def col_offset(self, bank: np.ndarray, row: np.ndarray) -> np.ndarray:
        """Shift (m) of the plot boundaries along row ``row`` of ``bank``, in [0, ``plot_length``)."""
        return self.plot_length * hash01(bank, row, seed=self.seed + 17)


@dataclass
class PlotIndex:
    """Per-cell plot lookup: bank (+1 right, −1 left, 0 valley floor), row, column, distances."""

    bank: np.ndarray
    a: np.ndarray
    row: np.ndarray
    col: np.ndarray
    d_row: np.ndarray  # distance to the nearest row boundary (m)
    d_col: np.ndarray  # distance to the nearest plot boundary along the row (m)
    d_row_signed_lo: np.ndarray  # a − lower boundary of the row
    row_hi_nearer: np.ndarray  # True where the upper row boundary is the nearer one


def _locate(x, step, bounds_fn):
    """Index i with bounds_fn(i) <= x < bounds_fn(i+1) for jittered boundaries (|jitter| < step/2)."""
    k0 = np.floor(x / step).astype(np.int64)
    lo = bounds_fn(k0)
    hi = bounds_fn(k0 + 1)
    k = k0 - (x < lo) + (x >= hi)
    return k


def plot_index(valley: Valley, fields: Fields, u: np.ndarray, vp: np.ndarray) -> PlotIndex:
    """Locate every cell in the field layout; O(n).

    Parameters
    ----------
    valley : Valley
        The valley; gives the floor half-width.
    fields : Fields
        The field layout.
    u, vp : ndarray
        Along-valley position and signed distance from the axis (m, right bank > 0) of each cell.

    Returns
    -------
    PlotIndex
        Bank, row, plot and boundary distances per cell.
    """
    bank = np.where(vp >= 0, 1, -1).astype(np.int64)
    a = np.abs(vp) - valley.floor_half_width - fields.floor_margin
    bank = np.where(a < 0, 0, bank)
    a_pos = np.clip(a, 0.0, None)
    row = _locate(a_pos, fields.row_depth, lambda k: fields.row_boundary(bank, k))
    lo = fields.row_boundary(bank, row)
    hi = fields.row_boundary(bank, row + 1)
    c = u + fields.col_offset(bank, row)
    col = _locate(c, fields.plot_length, lambda j: fields.col_boundary(bank, row, j))
    clo = fields.col_boundary(bank, row, col)
    chi = fields.col_boundary(bank, row, col + 1)
    d_row = np.minimum(a_pos - lo, hi - a_pos)
    d_col = np.minimum(c - clo, chi - c)
    return PlotIndex(bank=bank, a=a, row=row, col=col, d_row=d_row, d_col=d_col,
                     d_row_signed_lo=a_pos - lo, row_hi_nearer=(hi - a_pos) < (a_pos - lo))


def plot_class(fields: Fields, pi: PlotIndex) -> np.ndarray:
    """Class code of each plot (ploughed, grass or bare_eroded); valley floor gets 0."""
    h = hash01(pi.bank, pi.row, pi.col, seed=fields.seed + 19)
    cls = np.where(h < fields.share_ploughed, CODE["ploughed"],
                   np.where(h < fields.share_ploughed + fields.share_grass, CODE["grass"], CODE["bare_eroded"]))
    return np.where(pi.bank == 0, 0, cls).astype(np.uint8)


def tillage_angle(fields: Fields, pi: PlotIndex) -> np.ndarray:
    """Tillage direction per plot in the (u, a) frame (rad): 0 along the contour, π/2 downslope."""
    h = hash01(pi.bank, pi.row, pi.col, seed=fields.seed + 23)
    jit = np.deg2rad(10.0) * (2.0 * hash01(pi.bank, pi.row, pi.col, seed=fields.seed + 29) - 1.0)
    return np.where(h < fields.contour_share, 0.0, 0.5 * np.pi) + jit


def furrow_phase(fields: Fields, pi: PlotIndex, u: np.ndarray) -> np.ndarray:
    """Coordinate across the furrows (m); furrows run along the tillage direction.

    Parameters
    ----------
    fields : Fields
        The field layout.
    pi : PlotIndex
        Plot lookup of the cells.
    u : ndarray
        Along-valley position of the cells (m).

    Returns
    -------
    ndarray
        Phase coordinate (m) per cell.
    """
    th = tillage_angle(fields, pi)
    return -u * np.sin(th) + pi.a * np.cos(th)


def field_humps(fields: Fields, pi: PlotIndex) -> np.ndarray:
    """Small earth banks along plot boundaries (m), Gaussian cross-profile."""
    d = np.minimum(pi.d_row, pi.d_col)
    h = fields.hump_height * np.exp(-((d / fields.hump_width) ** 2))
    return np.where(pi.bank == 0, 0.0, h)


def tree_heights(fields: Fields, trees: dict, pi: PlotIndex, u: np.ndarray) -> np.ndarray:
    """Crown heights (m) of the tree rows planted on some row boundaries (0 elsewhere).

    Parameters
    ----------
    fields : Fields
        The field layout.
    trees : mapping
        ``twin.landcover.trees``; reads ``row_share``, ``spacing_m`` (m), ``crown_radius_m`` and
        ``height_m`` (ranges, m).
    pi : PlotIndex
        Plot lookup of the cells.
    u : ndarray
        Along-valley position of the cells (m).

    Returns
    -------
    ndarray float64
        Crown height (m) per cell.
    """
    k_b = np.where(pi.row_hi_nearer, pi.row + 1, pi.row)
    is_row = (hash01(pi.bank, k_b, seed=fields.seed + 31) < trees["row_share"]) & (pi.bank != 0) & (k_b >= 1)
    spacing = trees["spacing_m"]
    r0, r1 = trees["crown_radius_m"]
    h0, h1 = trees["height_m"]
    m0 = np.round(u / spacing - 0.5).astype(np.int64)
    out = np.zeros(u.shape, dtype=np.float64)
    for dm in (-1, 0, 1):
        m = m0 + dm
        hu = hash01(pi.bank, k_b, m, seed=fields.seed + 37)
        um = (m + 0.5 + 0.3 * (2.0 * hu - 1.0)) * spacing
        rad = r0 + (r1 - r0) * hash01(pi.bank, k_b, m, seed=fields.seed + 41)
        hgt = h0 + (h1 - h0) * hash01(pi.bank, k_b, m, seed=fields.seed + 43)
        d2 = (u - um) ** 2 + pi.d_row**2
        crown = hgt * np.sqrt(np.clip(1.0 - d2 / rad**2, 0.0, None)) ** 0.6
        out = np.maximum(out, crown)
    return np.where(is_row, out, 0.0)


def track_mask(valley: Valley, tracks: dict, u: np.ndarray, vp: np.ndarray) -> np.ndarray:
    """Dirt tracks: wavy lines along the banks and, optionally, along the dam crest.

    Parameters
    ----------
    valley : Valley
        The valley; gives the dam position and half-length.
    tracks : mapping
        ``twin.landcover.tracks``; reads ``width_m``, ``wave_amplitude_m``, ``wave_wavelength_m``,
        ``offsets_m`` (across-valley offsets of the tracks from the axis, m) and ``over_dam``.
    u, vp : ndarray
        Along-valley position and signed distance from the axis (m) of each cell.

    Returns
    -------
    ndarray bool
        True on a track.
    """
    half = 0.5 * tracks["width_m"]
    m = np.zeros(u.shape, dtype=bool)
    wave = tracks["wave_amplitude_m"] * np.sin(2.0 * np.pi * u / tracks["wave_wavelength_m"])
    for off in tracks["offsets_m"]:
        m |= np.abs(vp - off - wave) <= half
    if tracks["over_dam"]:
        m |= (np.abs(u - valley.u_dam) <= half) & (np.abs(vp) <= valley.dam_half_length)
    return m


def building_heights(buildings: list[dict], x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Roof elevation (m) inside building footprints, −inf elsewhere (few buildings: loop).

    Parameters
    ----------
    buildings : list of dict
        Buildings as from :func:`kitegully.twin.site.place_buildings` (``x``, ``y``, ``length_m``,
        ``width_m``, ``angle_rad``, ``roof_z``).
    x, y : ndarray
        Map coordinates (m); broadcast together.

    Returns
    -------
    ndarray float64
        Roof elevation (m) per point.
    """
    out = np.full(np.broadcast(x, y).shape, -np.inf)
    for b in buildings:
        c, s = np.cos(b["angle_rad"]), np.sin(b["angle_rad"])
        dx, dy = x - b["x"], y - b["y"]
        along = dx * c + dy * s
        across = -dx * s + dy * c
        inside = (np.abs(along) <= 0.5 * b["length_m"]) & (np.abs(across) <= 0.5 * b["width_m"])
        out = np.where(inside, np.maximum(out, b["roof_z"]), out)
    return out


def noise01(xs: np.ndarray, ys: np.ndarray, seed: int, wavelength: float) -> np.ndarray:
    """Two-octave value noise normalised to about [−1, 1] (patch patterns).

    Parameters
    ----------
    xs, ys : ndarray
        Column and row coordinates of the grid (m).
    seed : int
        Seed of the noise field.
    wavelength : float
        Wavelength of the coarser octave (m); the second has half of it.

    Returns
    -------
    ndarray (len(ys), len(xs)) float64
    """
    n = fbm_grid(xs, ys, seed, np.array([wavelength, 0.5 * wavelength]), np.array([1.0, 0.5]))
    return n / 1.5
