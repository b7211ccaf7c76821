"""Reading ground-control files: OpenDroneMap ``gcp_list.txt`` and a plain CSV form.

ODM format: the first non-comment line is the projection (``EPSG:2180``, a PROJ string
such as ``+proj=utm +zone=32 +datum=WGS84``, or ``WGS84 UTM 32N``); each further line is
``geo_x geo_y geo_z im_x im_y image_name [gcp_name] [extra ...]``. Lines without a name
are grouped into GCPs by identical planimetric coordinates (to the millimetre).

CSV format: header ``gcp_id,x,y,z,image,px,py`` with coordinates in the CRS given by the
caller (``georef.csv_crs``, the site CRS when null).

Pixel coordinates are kept as written; which frame they refer to (stored pixels or the
EXIF-rotated display, and at which scale) is the caller's switch
(``georef.gcp_pixel_frame``, ``georef.gcp_pixel_scale``), see
:func:`kitegully.sfm.images.to_sfm_pixels`.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
from pyproj import CRS, Transformer
from pyproj.exceptions import CRSError

from kitegully import InputError


@dataclass
class GCP:
    """One ground control point and its image observations.

    Attributes
    ----------
    gcp_id : str
        Name from the file, or ``GCP<n>`` in order of first appearance.
    xyz : ndarray (3,)
        Surveyed position in the site CRS (m); the median when rows disagree.
    images : list[str]
        Image file names of the observations.
    pixels : ndarray (n, 2)
        Pixel coordinates as written in the file.
    coord_spread_m : float
        Largest distance between the coordinates different rows give for this GCP.
    """

    gcp_id: str
    xyz: np.ndarray
    images: list[str] = field(default_factory=list)
    pixels: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    coord_spread_m: float = 0.0


_UTM = re.compile(r"^\s*WGS\s*84\s+UTM\s+(\d{1,2})\s*([NS])\s*$", re.IGNORECASE)


def parse_projection(line: str, path: str | Path = "") -> CRS:
    """CRS of an ODM projection line (EPSG code, PROJ string or ``WGS84 UTM <zone><N|S>``)."""
    text = line.strip()
    m = _UTM.match(text)
    try:
        if m:
            zone, hemi = int(m.group(1)), m.group(2).upper()
            if not 1 <= zone <= 60:
                raise CRSError(f"UTM zone {zone} out of range")
            return CRS.from_epsg((32600 if hemi == "N" else 32700) + zone)
        return CRS.from_user_input(text)
    except CRSError as exc:
        raise InputError(f"{path}: line 1: projection '{text}' is not understood ({exc})") from None


def _group(rows: list[tuple], path: Path) -> list[GCP]:
    """Group (x, y, z, px, py, image, name) rows into GCPs."""
    groups: dict[str, list[tuple]] = {}
    for r in rows:
        key = r[6] if r[6] else f"{r[0]:.3f}_{r[1]:.3f}"
        groups.setdefault(key, []).append(r)
    gcps = []
    for n, (key, members) in enumerate(groups.items(), start=1):
        xyz = np.array([m[:3] for m in members], dtype=float)
        med = np.median(xyz, axis=0)
        spread = float(np.max(np.linalg.norm(xyz[:, None] - xyz[None], axis=2))) if len(xyz) > 1 else 0.0
        name = members[0][6] or f"GCP{n}"
        gcps.append(
            GCP(name, med, [m[5] for m in members], np.array([m[3:5] for m in members], dtype=float), spread)
        )
    return gcps


def read_odm_gcp_list(path: str | Path, site_crs: str) -> list[GCP]:
    """Parse an ODM ``gcp_list.txt`` and reproject the GCPs to ``site_crs``.

    Raises
    ------
    InputError
        Naming the file and line of a malformed row, or an unknown projection.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: GCP file not found")
    lines = [(i + 1, ln.strip()) for i, ln in enumerate(path.read_text(encoding="utf-8-sig").splitlines())]
    lines = [(i, ln) for i, ln in lines if ln and not ln.startswith("#")]
    if not lines:
        raise InputError(f"{path}: GCP file is empty")
    src = parse_projection(lines[0][1], path)
    rows = []
    for lineno, ln in lines[1:]:
        parts = ln.split()
        if len(parts) < 6:
            raise InputError(f"{path}: line {lineno}: expected 'geo_x geo_y geo_z im_x im_y image_name [gcp_name]', got '{ln}'")
        try:
            x, y, z, px, py = (float(v) for v in parts[:5])
        except ValueError:
            raise InputError(f"{path}: line {lineno}: non-numeric coordinate in '{ln}'") from None
        if not np.all(np.isfinite([x, y, z, px, py])) or px < 0 or py < 0:
            raise InputError(f"{path}: line {lineno}: invalid (non-finite or negative) value in '{ln}'")
        name = parts[6] if len(parts) > 6 else ""
        rows.append((x, y, z, px, py, parts[5], name))
    if not rows:
        raise InputError(f"{path}: GCP file has a projection line but no observations")
    gcps = _group(rows, path)
    return _reproject(gcps, src, site_crs, path)


def read_gcp_csv(path: str | Path, site_crs: str, csv_crs: str | None = None) -> list[GCP]:
    """Parse the CSV form (``gcp_id,x,y,z,image,px,py``) and reproject to ``site_crs``.

    Parameters
    ----------
    path : str or Path
        The CSV GCP file.
    site_crs : str
        CRS to reproject the GCPs to.
    csv_crs : str or None
        CRS of the file's coordinates; None = ``site_crs``.

    Returns
    -------
    list of GCP
        The GCPs in the site CRS (m), rows grouped by ``gcp_id``.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: GCP file not found")
    try:
        df = pd.read_csv(path)
    except Exception as exc:  # pandas raises several parser errors
        raise InputError(f"{path}: cannot read CSV ({exc})") from None
    need = ["gcp_id", "x", "y", "z", "image", "px", "py"]
    missing = [c for c in need if c not in df.columns]
    if missing:
        raise InputError(f"{path}: missing column(s) {', '.join(missing)}; expected {', '.join(need)}")
    num = df[["x", "y", "z", "px", "py"]].apply(pd.to_numeric, errors="coerce")
    bad = num.isna().any(axis=1) | (num["px"] < 0) | (num["py"] < 0)
    if bad.any():
        raise InputError(f"{path}: line {int(np.flatnonzero(bad.to_numpy())[0]) + 2}: missing or non-numeric value")
    rows = [
        (r.x, r.y, r.z, r.px, r.py, str(img), str(gid))
        for r, img, gid in zip(num.itertuples(), df["image"], df["gcp_id"])
    ]
    src = CRS.from_user_input(csv_crs or site_crs)
    return _reproject(_group(rows, path), src, site_crs, path)


def _reproject(gcps: list[GCP], src: CRS, site_crs: str, path: Path) -> list[GCP]:
    dst = CRS.from_user_input(site_crs)
    if src.equals(dst):
        return gcps
    tr = Transformer.from_crs(src, dst, always_xy=True)
    xyz = np.array([g.xyz for g in gcps])
    x, y, z = tr.transform(xyz[:, 0], xyz[:, 1], xyz[:, 2])
    out = np.column_stack([x, y, z])
    if not np.all(np.isfinite(out)):
        raise InputError(f"{path}: GCP coordinates cannot be transformed from {src.to_string()} to {site_crs}")
    for g, p in zip(gcps, out):
        g.xyz = p
    return gcps


def read_gcps(path: str | Path, site_crs: str, fmt: str = "auto", csv_crs: str | None = None) -> list[GCP]:
    """Read a GCP file in ``fmt`` (``odm``, ``csv`` or ``auto`` by suffix).

    Parameters
    ----------
    path : str or Path
        The GCP file.
    site_crs : str
        CRS to reproject the GCPs to.
    fmt : str
        ``odm``, ``csv`` or ``auto`` (``csv`` for a ``.csv`` suffix, else ``odm``).
    csv_crs : str or None
        CRS of a CSV file's coordinates; None = ``site_crs``. Not used for ODM files.

    Returns
    -------
    list of GCP
        The GCPs in the site CRS (m).
    """
    if fmt == "auto":
        fmt = "csv" if Path(path).suffix.lower() == ".csv" else "odm"
    if fmt == "csv":
        return read_gcp_csv(path, site_crs, csv_crs)
    return read_odm_gcp_list(path, site_crs)


def read_tape_distances(path: str | Path) -> pd.DataFrame:
    """Tape-measured distances between GCP markers: CSV ``gcp_a,gcp_b,distance_m``."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: tape-distance file not found")
    df = pd.read_csv(path)
    need = ["gcp_a", "gcp_b", "distance_m"]
    if any(c not in df.columns for c in need):
        raise InputError(f"{path}: expected columns {', '.join(need)}")
    d = pd.to_numeric(df["distance_m"], errors="coerce")
    if d.isna().any() or (d <= 0).any():
        raise InputError(f"{path}: distance_m must be positive numbers")
    df["gcp_a"] = df["gcp_a"].astype(str)
    df["gcp_b"] = df["gcp_b"].astype(str)
    df["distance_m"] = d
    return df
