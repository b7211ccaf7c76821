"""Photographs: readable, complete, distinct, enough of them, one camera; their EXIF GPS if any."""

from __future__ import annotations

import hashlib
import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import piexif
from PIL import Image, UnidentifiedImageError

from kitegully import InputError
from kitegully.inputs.findings import Findings
from kitegully.sfm.images import exif_camera, exif_orientation, list_images

log = logging.getLogger(__name__)

MIN_PHOTOS = 3  # two views make no block to check; three is the least SfM can verify


@dataclass(frozen=True)
class Photo:
    """What the checks need of one photograph.

    Attributes
    ----------
    name : str
        File name (what GCP files use).
    width, height : int
        Stored pixel size (px).
    orientation : int
        EXIF orientation tag (1 when absent).
    camera : str
        ``Make Model`` from EXIF ("unknown camera" when absent).
    lon, lat, alt : float
        EXIF GPS position (degrees, degrees, m above sea level); NaN when absent.
    """

    name: str
    width: int
    height: int
    orientation: int
    camera: str
    lon: float
    lat: float
    alt: float

    def size_in(self, frame: str) -> tuple[int, int]:
        """(width, height) in the ``stored`` or EXIF-rotated ``display`` frame."""
        if frame == "display" and self.orientation in (5, 6, 7, 8):
            return self.height, self.width
        return self.width, self.height


def _dms(value, ref: bytes | None) -> float:
    try:
        d = sum(float(n) / float(q) / 60.0**k for k, (n, q) in enumerate(value))
    except (TypeError, ValueError, ZeroDivisionError):
        return float("nan")
    return -d if ref in (b"S", b"W") else d


def _gps(exif: dict) -> tuple[float, float, float]:
    g = exif.get("GPS", {}) or {}
    if piexif.GPSIFD.GPSLatitude not in g or piexif.GPSIFD.GPSLongitude not in g:
        return float("nan"), float("nan"), float("nan")
    lat = _dms(g[piexif.GPSIFD.GPSLatitude], g.get(piexif.GPSIFD.GPSLatitudeRef))
    lon = _dms(g[piexif.GPSIFD.GPSLongitude], g.get(piexif.GPSIFD.GPSLongitudeRef))
    alt = float("nan")
    if piexif.GPSIFD.GPSAltitude in g:
        n, q = g[piexif.GPSIFD.GPSAltitude]
        alt = n / q if q else float("nan")
        if g.get(piexif.GPSIFD.GPSAltitudeRef) == 1:
            alt = -alt
    return lon, lat, alt


def _camera(exif: dict) -> str:
    return exif_camera(exif) or "unknown camera"


def check_photos(images_dir: str | Path, found: Findings) -> list[Photo]:
    """Read every photograph completely; record what is wrong in ``found``.

    Errors: folder missing or empty, unreadable or truncated files (all named in one
    sentence), the same content under two names, fewer than three readable photos, a
    camera (EXIF make, model and pixel size) with fewer than three photos when there are
    several (SfM calibrates one camera group each; several cameras alone are a warning).
    Time O(total pixels), one image in memory at a time.

    Returns
    -------
    list of Photo
        The readable photographs.
    """
    src = str(images_dir)
    try:
        files = list_images(images_dir)
    except InputError as exc:
        found.error(src, str(exc).removeprefix(f"{src}: "))
        return []
    photos, bad, digests = [], [], {}
    dups = []
    for path in files:
        try:
            with Image.open(path) as im:
                im.load()
                w, h = im.size
        except Exception as exc:  # any decoder error: unreadable or truncated
            reason = str(exc).split("\n")[0]
            if isinstance(exc, UnidentifiedImageError):
                reason = "not an image file"
            elif "truncated" in reason.lower():
                reason = "truncated"
            bad.append(f"{path.name} ({reason})")
            continue
        digest = hashlib.sha1(path.read_bytes()).hexdigest()
        if digest in digests:
            dups.append(f"{path.name} = {digests[digest]}")
        digests.setdefault(digest, path.name)
        try:
            exif = piexif.load(str(path))
        except Exception:  # no EXIF block (PNG, some TIFF)
            exif = {}
        camera = f"{_camera(exif)} {max(w, h)}x{min(w, h)} px"
        photos.append(Photo(path.name, w, h, exif_orientation(path), camera, *_gps(exif)))
    if bad:
        found.error(src, f"unreadable or truncated image(s): {', '.join(bad)}")
    if dups:
        found.error(src, f"the same photograph under two names: {', '.join(dups)}; remove the copies")
    if files and len(photos) < MIN_PHOTOS:
        found.error(src, f"only {len(photos)} readable photograph(s); structure from motion needs at least {MIN_PHOTOS}")
    cameras: dict[str, int] = {}
    for p in photos:
        cameras[p.camera] = cameras.get(p.camera, 0) + 1
    if len(cameras) > 1:
        groups = "; ".join(f"{c}: {n}" for c, n in sorted(cameras.items(), key=lambda kv: -kv[1]))
        small = [c for c, n in cameras.items() if n < MIN_PHOTOS]
        if small:
            found.error(src, f"photographs from {len(cameras)} cameras ({groups}); each camera is calibrated on its own, "
                             f"so each needs at least {MIN_PHOTOS} photos: remove the odd ones or add more")
        else:
            found.warning(src, f"photographs from {len(cameras)} cameras ({groups}); SfM calibrates one camera group each")
    has_gps = sum(np.isfinite(p.lat) for p in photos)
    found.facts.update(n_photos=len(photos), cameras=cameras, n_photos_with_gps=int(has_gps))
    if photos and has_gps == 0:
        found.note(src, "no photograph has an EXIF GPS position, so control points cannot be checked against the camera positions")
    log.info("%d photographs read from %s (%d with EXIF GPS)", len(photos), src, has_gps)
    return photos
