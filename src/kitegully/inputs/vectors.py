"""Vector files handed in (gully heads, reference network, catchment): readable, with the site's CRS."""

from __future__ import annotations

from pathlib import Path

import pyogrio
from pyproj import CRS

from kitegully.inputs.crs import crs_label
from kitegully.inputs.findings import Findings


def check_vector(path: str | Path, key: str, site_crs: CRS, found: Findings) -> None:
    """Check one vector file named by config key ``key``; record errors in ``found``. Reads the header only.

    Parameters
    ----------
    path : str or Path
        The vector file.
    key : str
        Config key naming the file, e.g. ``gully.heads_file``.
    site_crs : CRS
        The site CRS; the layer's CRS must equal it.
    found : Findings
        Collects the errors: missing or unreadable file, no CRS, another CRS, no features.
    """
    path = Path(path)
    src = str(path)
    if not path.is_file():
        found.error(src, f"file named in {key} not found")
        return
    try:
        info = pyogrio.read_info(path)
    except Exception as exc:  # pyogrio raises DataSourceError and others on unreadable files
        found.error(src, f"not a readable vector file ({str(exc).splitlines()[0].split(';')[0]})")
        return
    if not info.get("crs"):
        found.error(src, f"the layer has no CRS; it must be in the site CRS {crs_label(site_crs)}")
        return
    crs = CRS.from_user_input(info["crs"])
    if not crs.equals(site_crs, ignore_axis_order=True):
        found.error(src, f"the layer is in {crs_label(crs)}, not the site CRS {crs_label(site_crs)}; reproject it first")
        return
    if info.get("features", 0) == 0:
        found.error(src, f"the layer named in {key} has no features")
