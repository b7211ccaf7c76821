"""Profiles draped on the DEM and the depth reference they are measured against (Höfle et al. 2013 sect. 4.3).

A line sampled on the DEM (:func:`drape`), its ground under low vegetation (:func:`ground_profile`,
a 1-D grey opening), the floor's gradient along a medial axis (:func:`axis_gradient`), the
section's depth and area below a reference (:func:`section_profile`) and the pre-incision
surface fitted to the banks beyond both rims (:func:`bank_reference`).
"""

from __future__ import annotations

import numpy as np
import scipy.ndimage as ndi
import shapely
from scipy.ndimage import map_coordinates

from kitegully.io.raster import GridSpec

#: Depth reference surfaces (``polygons.morphometry.reference``).
REFERENCES = ("lower_end", "line", "spill", "banks", "bank_lines")


def drape(line: shapely.LineString, surface: np.ndarray, grid: GridSpec, step: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Points every ``step`` m along ``line`` (ends included): s, x, y and bilinear z.

    Parameters
    ----------
    line : LineString
        Line in map coordinates.
    surface : ndarray (H, W)
        Surface to sample (m).
    grid : GridSpec
        Grid of ``surface``.
    step : float
        Largest sample spacing (m); the samples are spread evenly over the line.

    Returns
    -------
    s, x, y, z : ndarray (n,)
        Distance along the line (m), map coordinates and the surface's elevation (m).
    """
    n = max(int(np.ceil(line.length / step)), 1)
    s = np.linspace(0.0, line.length, n + 1)
    pts = shapely.line_interpolate_point(line, s)
    x, y = shapely.get_x(pts), shapely.get_y(pts)
    r, c = grid.rowcol(x, y)
    z = map_coordinates(surface, [r, c], order=1, mode="nearest")
    return s, x, y, z


def axis_gradient(axis: shapely.LineString, s0: float, dem: np.ndarray, grid: GridSpec, step: float, segment_m: float) -> float:
    """The floor's gradient along a medial axis at ``s0`` (m/m, positive uphill in the axis' direction).

    The slope of a straight line fitted (least squares) to the axis' ground profile (the DEM
    draped along the axis from ``s0 − 2·segment_m`` to ``s0 + 2·segment_m``, opened with
    ``segment_m`` as :func:`ground_profile`, so that a clump in the channel does not tilt it)
    over ``s0 ± segment_m``. 0 where the axis is too short for two samples. O(segment / step).

    Parameters
    ----------
    axis : LineString
        The medial axis.
    s0 : float
        Position along the axis (m).
    dem : ndarray (H, W)
        DEM (m).
    grid : GridSpec
        Grid of ``dem``.
    step : float
        Sample spacing along the axis (m).
    segment_m : float
        Half-length of the fitted stretch and length of the opening segment (m).

    Returns
    -------
    float
        Gradient (m/m).
    """
    a, b = max(s0 - 2.0 * segment_m, 0.0), min(s0 + 2.0 * segment_m, axis.length)
    if b - a < 2.0 * step:
        return 0.0
    piece = shapely.ops.substring(axis, a, b)
    s, _, _, z = drape(piece, dem, grid, step)
    g = ground_profile(z, float(s[1] - s[0]) if s.size > 1 else step, segment_m)
    tau = s + a - s0
    sel = (np.abs(tau) <= segment_m + 1e-9) & np.isfinite(g)
    if sel.sum() < 2:
        return 0.0
    return float(np.polyfit(tau[sel], g[sel], 1)[0])


def drape_opened_along(line: shapely.LineString, surface: np.ndarray, grid: GridSpec, step: float, along: np.ndarray,
                       gradient: float, segment_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`drape`, with each sample's elevation opened along the gully (the ground between plants along the strip).

    The line is draped again shifted by τ in [−``segment_m``, +``segment_m``] (every ``step``)
    along the unit vector ``along`` (the gully axis), each copy detrended by ``gradient`` · τ
    (the floor's gradient along the axis, :func:`axis_gradient`, so that a rim is not bevelled
    by the gully's fall), and at each position the samples along τ are opened with a
    ``segment_m`` segment (:func:`ground_profile`'s 1-D grey opening); the value at τ = 0 is
    returned. A plant clump narrower than the segment along the strip is removed where ground
    shows beside it along the gully; a clump the opening across the section cannot see past
    (its gap to the next clump across is filled by the matching window) is seen past along it.
    Never above :func:`drape`'s z (the opening is anti-extensive and τ = 0 is not detrended).

    Parameters
    ----------
    line : LineString
        The section in map coordinates.
    surface : ndarray (H, W)
        Surface to sample (m).
    grid : GridSpec
        Grid of ``surface``.
    step : float
        Sample spacing along the line and along the axis (m).
    along : ndarray (2,)
        Unit vector of the gully axis (x east, y north).
    gradient : float
        Floor gradient along ``along`` (m/m).
    segment_m : float
        Length of the opening segment along the axis (m); 0 = :func:`drape` unchanged.

    Returns
    -------
    s, x, y, z : ndarray
        As :func:`drape`. O(n · segment / step) for n samples.
    """
    s, x, y, z0 = drape(line, surface, grid, step)
    k = int(round(segment_m / step))
    if segment_m <= 0 or k < 1:
        return s, x, y, z0
    tau = np.arange(-k, k + 1) * step
    shifted = tau != 0  # the τ = 0 row is drape's own z0, not sampled twice
    xs = x[None, :] + tau[shifted, None] * along[0]
    ys = y[None, :] + tau[shifted, None] * along[1]
    r, c = grid.rowcol(xs.ravel(), ys.ravel())
    zz = np.empty((tau.size, s.size))
    zz[shifted] = map_coordinates(surface, [r, c], order=1, mode="nearest").reshape(xs.shape) - gradient * tau[shifted, None]
    zz[k] = z0
    ok = np.isfinite(zz)
    zz = np.where(ok, zz, np.nanmax(zz) if ok.any() else 0.0)
    opened = ndi.grey_opening(zz, size=(k + 1, 1), mode="nearest")[k]
    return s, x, y, np.where(np.isfinite(z0), np.minimum(opened, z0), z0)


def section_profile(s: np.ndarray, z: np.ndarray, reference: str, level: np.ndarray | None = None) -> tuple[float, float]:
    """(max depth, cross-sectional area) of a draped section below the reference surface.

    ``level`` is the reference surface itself along ``s`` for ``spill`` (the pool level),
    ``banks`` and ``bank_lines`` (:func:`bank_reference`).

    Parameters
    ----------
    s : ndarray (n,)
        Distance along the section (m).
    z : ndarray (n,)
        Elevations at ``s`` (m).
    reference : str
        Depth reference (:data:`REFERENCES`).
    level : ndarray (n,) or None
        Reference surface at ``s`` (m) for ``spill``, ``banks`` and ``bank_lines``.

    Returns
    -------
    depth : float
        Largest depth below the reference (m).
    area : float
        Cross-sectional area below the reference (m²).
    """
    if reference == "lower_end":
        zr = np.full_like(z, min(z[0], z[-1]))
    elif reference == "line":
        zr = z[0] + (z[-1] - z[0]) * (s / s[-1] if s[-1] > 0 else 0.0)
    elif reference in ("spill", "banks", "bank_lines"):
        zr = level
    else:
        raise ValueError(f"reference must be one of {REFERENCES}, got {reference!r}")
    d = np.maximum(np.nan_to_num(zr - z, nan=0.0), 0.0)
    area = float(np.sum(0.5 * (d[1:] + d[:-1]) * np.diff(s))) if len(s) > 1 else 0.0
    return float(d.max()), area


def ground_profile(z: np.ndarray, step: float, segment_m: float) -> np.ndarray:
    """Ground of a draped profile under plants narrower than ``segment_m``: 1-D grey opening.

    The opening (minimum, then maximum, over ``segment_m``) removes every bump narrower than
    the segment (a shrub clump on a rim stands on ground the segment reaches beside it) and
    keeps every concave part (a gully floor) and every straight one (a field's cross slope)
    unchanged (the progressive morphological filter of Zhang et al. 2003, one window, along
    the section). Across a gully the profile's only convex corners are the rims: a rim whose
    field rises outwards is kept; one whose field falls outwards at cross slope c is lowered
    by at most c · ``segment_m``.

    Parameters
    ----------
    z : ndarray (n,)
        Elevations every ``step`` m along the section (m); NaN are left as they are.
    step : float
        Sample spacing (m).
    segment_m : float
        Segment length (m): the widest plant clump to be removed; 0 = ``z`` unchanged.

    Returns
    -------
    ndarray (n,)
        The ground profile (≤ ``z``); within one segment of either end it may lie low (the
        opening sees past the end), so callers drape the section prolonged by one segment at
        both ends (:func:`_ground_drape`). O(n · segment / step).
    """
    k = int(round(segment_m / step)) + 1
    if segment_m <= 0 or k < 2 or z.size < k:
        return z
    ok = np.isfinite(z)
    zz = np.where(ok, z, np.nanmax(z) if ok.any() else 0.0)
    g = ndi.grey_opening(zz, size=k, mode="nearest")
    return np.where(ok, g, z)


#: Samples within this distance (m) of a section end count as on it (:func:`bank_reference`).
END_TOL = 1e-9


def bank_reference(s: np.ndarray, z: np.ndarray, length: float, fit_m: float, model: str = "quadratic") -> np.ndarray:
    """Pre-incision surface across a gully from its two banks, on the samples ``0 <= s <= length``.

    The banks are the profile over ``fit_m`` outwards from each reference end (``s`` in
    [−fit_m, 0] and [length, length + fit_m]).

    - ``quadratic``: one parabola z = a + b·s + c·s² fitted (least squares) to both banks at once:
      on a plane (a hillside tilted across the gully) it is that plane, i.e. the straight line
      between the ends (``reference="line"``); in a hollow of constant curvature κ (where flow
      converges and gullies cut in) it is the hollow's own floor, κ·B²/8 below the straight line
      at the middle of a section of width B between the ends; in a V-shaped valley floor (sides
      of slope c) it takes part of the c·B/2 by which the straight line stands above the V.
    - ``lines``: a straight line fitted to each bank, both extended across the gully and blended
      linearly, z_ref(s) = (1 − s/L)·left(s) + (s/L)·right(s): exact on a plane and in a V-shaped
      valley floor, but in a hollow each bank's slope, taken a lever arm away from the gully,
      extrapolates below the hollow's floor.

    With fewer than two finite samples on either bank (no slope there) the straight line between
    the ends is returned.

    Parameters
    ----------
    s : ndarray (n,)
        Positions along the section prolonged beyond both reference ends (m; 0 = first end),
        increasing.
    z : ndarray (n,)
        Ground elevations at ``s`` (m); NaN = no data.
    length : float
        Position of the second reference end (m).
    fit_m : float
        Length of each bank beyond its end (m).
    model : str
        ``quadratic`` or ``lines``.

    Returns
    -------
    ndarray
        z_ref at the samples ``0 <= s <= length``. O(n).
    """
    inner = (s >= -END_TOL) & (s <= length + END_TOL)
    si, zi = s[inner], z[inner]
    L = max(float(length), 1e-9)
    t = np.clip(si / L, 0.0, 1.0)
    chord = zi[0] + (zi[-1] - zi[0]) * t if zi.size else zi
    left = (s >= -fit_m - END_TOL) & (s <= END_TOL) & np.isfinite(z)
    right = (s >= length - END_TOL) & (s <= length + fit_m + END_TOL) & np.isfinite(z)
    if model not in ("quadratic", "lines"):
        raise ValueError(f"model must be 'quadratic' or 'lines', got {model!r}")
    if left.sum() < 2 or right.sum() < 2:
        return chord
    if model == "quadratic":
        sel = left | right
        c2, c1, c0 = np.polyfit(s[sel], z[sel], 2)
        return c0 + si * (c1 + si * c2)
    else:
        bl, al = np.polyfit(s[left], z[left], 1)
        br, ar = np.polyfit(s[right], z[right], 1)
        return (1.0 - t) * (al + bl * si) + t * (ar + br * si)
