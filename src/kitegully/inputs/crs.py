"""Coordinate reference systems: the site's must be projected in metres; points must lie in its area of use."""

from __future__ import annotations

import numpy as np
from pyproj import CRS, Transformer
from pyproj.exceptions import CRSError

from kitegully import InputError

# [I] Slack around a CRS's published area of use (degrees): survey data a little outside a
# UTM zone (extended zones) is common and harmless; swapped axes or degrees are far outside.
AREA_MARGIN_DEG = 1.0


def site_crs(text: str, source: str = "site.crs") -> CRS:
    """The site CRS, refused unless it is a known projected CRS with metre units.

    Parameters
    ----------
    text
        What the configuration says (``EPSG:32632``, a PROJ string, WKT).
    source
        File and key named in the error, e.g. ``config/sites/x.yaml: site.crs``.

    Raises
    ------
    InputError
        Unknown CRS, a geographic CRS (degrees) or a projected CRS in feet.
    """
    try:
        crs = CRS.from_user_input(text)
    except CRSError:
        raise InputError(f"{source}: '{text}' is not a known CRS; give a projected CRS in metres such as EPSG:32632 (UTM 32N)") from None
    if crs.is_geographic:
        raise InputError(
            f"{source}: '{text}' is geographic (degrees); give a projected CRS in metres such as the site's UTM zone (EPSG:326xx north, EPSG:327xx south)"
        )
    if not crs.is_projected:
        raise InputError(f"{source}: '{text}' is not a projected CRS; give a projected CRS in metres such as EPSG:32632")
    units = {ax.unit_name for ax in crs.axis_info[:2]}
    if units != {"metre"}:
        raise InputError(f"{source}: '{text}' has units of {', '.join(sorted(units))}; kitegully needs a projected CRS in metres")
    return crs


def to_lonlat(crs: CRS, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Longitude and latitude (degrees) of points given in ``crs`` (x = easting/longitude).

    Parameters
    ----------
    crs : CRS
        CRS of the points.
    x, y : ndarray
        Coordinates of the points in ``crs``; returned as they are when ``crs`` is geographic.

    Returns
    -------
    lon, lat : ndarray float
        Degrees; not finite where the transformation fails.
    """
    if crs.is_geographic:
        return np.asarray(x, float), np.asarray(y, float)
    tr = Transformer.from_crs(crs, CRS.from_epsg(4326), always_xy=True)
    with np.errstate(all="ignore"):
        lon, lat = tr.transform(np.asarray(x, float), np.asarray(y, float), errcheck=False)
    return np.asarray(lon, float), np.asarray(lat, float)


def inside_area_of_use(crs: CRS, x: np.ndarray, y: np.ndarray, margin_deg: float = AREA_MARGIN_DEG) -> np.ndarray:
    """Boolean per point: inside the CRS's area of use (widened by ``margin_deg``). All True when pyproj has none.

    Parameters
    ----------
    crs : CRS
        CRS of the points.
    x, y : ndarray
        Coordinates of the points in ``crs``.
    margin_deg : float
        Slack around the area of use (degrees).

    Returns
    -------
    ndarray bool
        True for each point inside whose longitude and latitude also transform back to it (within 1 m,
        or 1e-6 under a geographic CRS), in the shape of ``x``.
    """
    aou = crs.area_of_use
    x, y = np.asarray(x, float), np.asarray(y, float)
    if aou is None:
        return np.ones(x.shape, bool)
    lon, lat = to_lonlat(crs, x, y)
    # a projection's inverse of absurd values may wrap around instead of failing: check the round trip
    back = Transformer.from_crs(CRS.from_epsg(4326), crs, always_xy=True)
    with np.errstate(all="ignore"):
        bx, by = back.transform(lon, lat, errcheck=False)
        tol = 1e-6 if crs.is_geographic else 1.0
        round_trip = np.isfinite(bx) & (np.hypot(np.asarray(bx) - x, np.asarray(by) - y) < tol)
        west, east = aou.west, aou.east
        lon_ok = (lon >= west - margin_deg) & (lon <= east + margin_deg) if west <= east else (lon >= west - margin_deg) | (lon <= east + margin_deg)
        lat_ok = (lat >= aou.south - margin_deg) & (lat <= aou.north + margin_deg)
    return np.isfinite(lon) & np.isfinite(lat) & lon_ok & lat_ok & round_trip


def area_name(crs: CRS) -> str:
    """The CRS's area of use, its first sentence (pyproj's full text lists every country)."""
    return crs.area_of_use.name.split(". ")[0].rstrip(".") if crs.area_of_use else "no published area"


def crs_label(crs: CRS) -> str:
    """Short name: ``EPSG:32632`` when it has a code, else its name."""
    code = crs.to_epsg()
    return f"EPSG:{code}" if code else crs.name


def check_coordinates(crs: CRS, x: np.ndarray, y: np.ndarray, lines: list[int], what: str) -> str | None:
    """The first thing wrong with planimetric coordinates in ``crs``, as a sentence; None when fine.

    Tests in order: degrees under a projected CRS, easting and northing swapped, points
    outside the CRS's area of use. ``lines`` are the file's line numbers of the points,
    ``what`` names them ("GCP", "checkpoint").

    Parameters
    ----------
    crs : CRS
        CRS the coordinates are declared in.
    x, y : ndarray
        Easting and northing (or longitude and latitude) of the points.
    lines : list of int
        Line number in the file of each point.
    what : str
        Name of the points in the sentence.

    Returns
    -------
    str or None
        The problem as a sentence; None when the coordinates are fine.
    """
    x, y = np.asarray(x, float), np.asarray(y, float)
    label = crs_label(crs)
    deg = (np.abs(x) <= 180.0) & (np.abs(y) <= 90.0)
    if crs.is_projected and deg.all():
        return (f"{what} coordinates look like degrees (x {x.min():.5g} to {x.max():.5g}, y {y.min():.5g} to {y.max():.5g}) "
                f"but {label} is in metres; give projected coordinates or declare the geographic CRS")
    if crs.is_projected and deg.any():
        k = int(np.flatnonzero(deg)[0])
        return (f"line {lines[k]}: x {x[k]:.6g}, y {y[k]:.6g} look like degrees but {label} is in metres; "
                f"give projected coordinates")
    inside = inside_area_of_use(crs, x, y)
    if np.all(inside):
        return None
    if not np.any(inside) and np.all(inside_area_of_use(crs, y, x)):
        return (f"easting and northing look swapped: line {lines[0]} has x {x[0]:.3f}, y {y[0]:.3f}, which lies outside "
                f"{label} ({area_name(crs)}), but swapped every {what} falls inside it")
    k = int(np.flatnonzero(~inside)[0])
    n_out = int((~inside).sum())
    return (f"{n_out} {what}(s) lie outside the area of use of {label} ({area_name(crs)}), "
            f"first on line {lines[k]} (x {x[k]:.3f}, y {y[k]:.3f}); check the CRS and the coordinates")
