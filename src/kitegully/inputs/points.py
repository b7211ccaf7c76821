"""Checks shared by GCP and checkpoint files: coordinates, heights, duplicates, distance to the photos."""

from __future__ import annotations

import numpy as np
from pyproj import CRS, Geod

from kitegully.inputs.crs import check_coordinates, crs_label, to_lonlat
from kitegully.inputs.findings import Findings
from kitegully.inputs.photos import Photo

Z_UNITS = {"m": 1.0, "ft": 0.3048, "us_ft": 1200.0 / 3937.0}

# [I] A kite photo block covers well under 1 km; EXIF GPS of a consumer camera is good to
# tens of metres. Control farther than this from every photo cannot be in the photos.
MAX_DISTANCE_TO_PHOTOS_M = 5000.0
# Highest terrain on Earth (m): no metre height can exceed it.
MAX_HEIGHT_M = 8850.0
# [I] Margin by which ground heights may exceed the cameras' GPS altitude before they are
# "above the cameras": consumer GPS altitude is good to a few tens of metres, and ellipsoidal
# GCP heights differ from the camera's sea-level altitude by the geoid undulation (|N| < 110 m).
ALTITUDE_SLACK_M = 100.0


def check_heights(z: np.ndarray, units: str, photos: list[Photo], found: Findings, src: str, what: str) -> bool:
    """Heights as written (in ``units``): feet that look like metres, placeholders. True when usable.

    Parameters
    ----------
    z : ndarray
        Heights as written, one per row.
    units : str
        Their units: ``m``, ``ft`` or ``us_ft``.
    photos : list of Photo
        The photographs; the heights in metres must not lie more than ``ALTITUDE_SLACK_M`` above
        the median EXIF GPS altitude.
    found : Findings
        Collects the findings.
    src : str
        The file, named in the findings.
    what : str
        Name of the points (``GCP``, ``checkpoint``).

    Returns
    -------
    bool
    """
    ok = True
    z_m = z * Z_UNITS[units]
    hint = "set inputs.z_units: ft (or us_ft) so they are converted" if units == "m" else "check inputs.z_units"
    if np.nanmax(np.abs(z_m)) > MAX_HEIGHT_M:
        found.error(src, f"{what} heights up to {np.nanmax(z):.1f} cannot be {units_name(units)}; if they are feet, {hint}")
        return False
    if heights_are_placeholders(z):
        if what == "GCP":
            found.warning(src, f"all {len(z)} GCP heights are {z[0]:g}, which looks like a placeholder, not surveyed "
                               "heights; the block will be georeferenced in plan only and its heights will be relative")
            found.facts["plan_only"] = True
            return True
        found.error(src, f"all {len(z)} {what} heights are {z[0]:g}, which looks like a placeholder, not surveyed heights; "
                         "checkpoints validate heights, so give surveyed heights or leave the checkpoint file out")
        return False
    alt = np.array([p.alt for p in photos], float)
    alt = alt[np.isfinite(alt)]
    if len(alt):
        cam = float(np.median(alt))
        med = float(np.median(z_m))
        if med > cam + ALTITUDE_SLACK_M:
            feet = med * 0.3048
            tail = (f"in feet they would be {feet:.0f} m, below the cameras; {hint}" if feet <= cam + ALTITUDE_SLACK_M
                    else "check the heights and their vertical datum")
            found.error(src, f"{what} heights (median {med:.1f} m) lie above the cameras' EXIF GPS altitude (median {cam:.1f} m); {tail}")
            ok = False
    return ok


def heights_are_placeholders(z: np.ndarray) -> bool:
    """True when two or more heights are all one value (0.0, -9999, ...): not surveyed heights.

    Parameters
    ----------
    z : array
        Heights as read from a control file (one per row).

    Returns
    -------
    bool
    """
    z = np.asarray(z, float)
    return len(z) >= 2 and bool(np.all(np.isfinite(z))) and float(np.ptp(z)) == 0.0


def units_name(units: str) -> str:
    """English name of a unit code, for messages.

    Parameters
    ----------
    units : str
        ``m``, ``ft`` or ``us_ft``.

    Returns
    -------
    str
        ``metres``, ``feet`` or ``US survey feet`` (KeyError for any other code).
    """
    return {"m": "metres", "ft": "feet", "us_ft": "US survey feet"}[units]


def check_points(
    crs: CRS, x: np.ndarray, y: np.ndarray, lines: list[int], photos: list[Photo], found: Findings, src: str, what: str,
) -> bool:
    """Planimetric checks: degrees, swapped axes, area of use, distance to the photos' GPS. True when fine.

    Parameters
    ----------
    crs : CRS
        CRS of the points.
    x, y : ndarray
        Coordinates of the points in ``crs``.
    lines : list of int
        Line number in the file of each point.
    photos : list of Photo
        The photographs; each point must lie within ``MAX_DISTANCE_TO_PHOTOS_M`` of one's EXIF GPS position.
    found : Findings
        Collects the first error and, with GPS, the largest distance to the photos.
    src : str
        The file, named in the findings.
    what : str
        Name of the points (``GCP``, ``checkpoint``).

    Returns
    -------
    bool
    """
    problem = check_coordinates(crs, x, y, lines, what)
    if problem:
        found.error(src, problem)
        return False
    if len(x) >= 3:
        d_med = np.hypot(x - np.median(x), y - np.median(y)) if crs.is_projected else np.zeros(len(x))
        k = int(np.argmax(d_med))
        if d_med[k] > MAX_DISTANCE_TO_PHOTOS_M:
            found.error(src, f"line {lines[k]}: {what} lies {d_med[k] / 1000:.1f} km from the middle of the others; "
                             "a photo block is far smaller, so check its coordinates")
            return False
    gps = [(p.lon, p.lat) for p in photos if np.isfinite(p.lat) and np.isfinite(p.lon)]
    if gps:
        lon, lat = to_lonlat(crs, x, y)
        plon, plat = np.array(gps).T
        geod = Geod(ellps="WGS84")
        d = np.array([
            geod.inv(np.full(len(plon), lo), np.full(len(plon), la), plon, plat)[2].min() for lo, la in zip(lon, lat)
        ])
        k = int(np.argmax(d))
        if d[k] > MAX_DISTANCE_TO_PHOTOS_M:
            found.error(src, f"{what} on line {lines[k]} is {d[k] / 1000:.0f} km from the nearest photograph's EXIF GPS position "
                             f"(the points must lie in the photos); check the CRS ({crs_label(crs)}) and the coordinates")
            return False
        found.facts[f"{what.lower()}_max_distance_to_photos_m"] = float(d.max())
    return True


def duplicate_lines(keys: list[tuple], lines: list[int]) -> list[tuple[int, int]]:
    """Pairs (first line, repeated line) of identical rows."""
    seen: dict[tuple, int] = {}
    out = []
    for key, ln in zip(keys, lines):
        if key in seen:
            out.append((seen[key], ln))
        else:
            seen[key] = ln
    return out
