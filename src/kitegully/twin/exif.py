"""EXIF for simulated photographs: what a real camera writes, so SfM reads the focal length.

Written tags: Make, Model, DateTimeOriginal (+ SubSecTimeOriginal), FocalLength,
FocalLengthIn35mmFilm, FocalPlaneX/YResolution with unit (cm), PixelX/YDimension,
ExposureTime. No GPS tags: like the NEX-5N of Feurer et al. (2018), the camera has no
receiver; a separate GPS logger records the track.
"""

from __future__ import annotations

from datetime import datetime
from fractions import Fraction
from pathlib import Path

import numpy as np
import piexif
from PIL import Image

from kitegully import InputError
from kitegully.twin.camera import Camera

FULL_FRAME_DIAGONAL_MM = float(np.hypot(36.0, 24.0))


def _rational(value: float, max_den: int = 10000) -> tuple[int, int]:
    fr = Fraction(value).limit_denominator(max_den)
    return fr.numerator, fr.denominator


def focal_35mm(camera: Camera) -> int:
    """35 mm equivalent focal length from the sensor diagonal (mm, rounded)."""
    diag = float(np.hypot(camera.sensor_width_mm, camera.sensor_height_mm))
    return int(round(camera.focal_length_mm * FULL_FRAME_DIAGONAL_MM / diag))


def exif_bytes(camera: Camera, when: datetime, exposure_time_s: float | None = None) -> bytes:
    """Serialised EXIF block for one image of ``camera`` taken at ``when``.

    Parameters
    ----------
    camera : Camera
        Make, model, image size, sensor size and focal length written to the tags.
    when : datetime
        Time the image was taken (DateTime, DateTimeOriginal, SubSecTimeOriginal in 1/100 s).
    exposure_time_s : float or None
        Exposure time (s); None or 0 writes no ExposureTime tag.

    Returns
    -------
    bytes
        The EXIF block as made by ``piexif.dump``, without GPS tags or thumbnail.
    """
    px_per_cm_x = camera.width / (camera.sensor_width_mm / 10.0)
    px_per_cm_y = camera.height / (camera.sensor_height_mm / 10.0)
    zeroth = {
        piexif.ImageIFD.Make: camera.make.encode(),
        piexif.ImageIFD.Model: camera.model.encode(),
        piexif.ImageIFD.Software: b"kitegully twin renderer",
        piexif.ImageIFD.DateTime: when.strftime("%Y:%m:%d %H:%M:%S").encode(),
    }
    exif = {
        piexif.ExifIFD.DateTimeOriginal: when.strftime("%Y:%m:%d %H:%M:%S").encode(),
        piexif.ExifIFD.DateTimeDigitized: when.strftime("%Y:%m:%d %H:%M:%S").encode(),
        piexif.ExifIFD.SubSecTimeOriginal: f"{when.microsecond // 10000:02d}".encode(),
        piexif.ExifIFD.FocalLength: _rational(camera.focal_length_mm),
        piexif.ExifIFD.FocalLengthIn35mmFilm: focal_35mm(camera),
        piexif.ExifIFD.FocalPlaneXResolution: _rational(px_per_cm_x),
        piexif.ExifIFD.FocalPlaneYResolution: _rational(px_per_cm_y),
        piexif.ExifIFD.FocalPlaneResolutionUnit: 3,
        piexif.ExifIFD.PixelXDimension: camera.width,
        piexif.ExifIFD.PixelYDimension: camera.height,
    }
    if exposure_time_s:
        exif[piexif.ExifIFD.ExposureTime] = _rational(exposure_time_s, 100000)
    return piexif.dump({"0th": zeroth, "Exif": exif, "GPS": {}, "1st": {}, "thumbnail": None})


def write_jpeg(path: str | Path, image: np.ndarray, exif: bytes, quality: int) -> None:
    """Write an 8-bit RGB (or single-channel) image as JPEG with the EXIF block.

    Parameters
    ----------
    path : str or Path
        The JPEG file; its parent folder is created.
    image : ndarray (H, W, 3) or (H, W) uint8
        The image; a single channel given as ``(H, W, 1)`` is written as greyscale.
    exif : bytes
        EXIF block, as from :func:`exif_bytes`.
    quality : int
        JPEG quality; 95 or more keeps full chroma resolution (no subsampling).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    arr = image[..., 0] if image.ndim == 3 and image.shape[2] == 1 else image
    Image.fromarray(arr).save(path, format="JPEG", quality=int(quality), exif=exif, subsampling=0 if quality >= 95 else 2)


def read_exif(path: str | Path) -> dict:
    """Main EXIF values of a JPEG as plain Python (make, model, focal lengths, time, size)."""
    try:
        d = piexif.load(str(path))
    except Exception as exc:  # piexif raises several types for non-JPEG input
        raise InputError(f"{path}: cannot read EXIF ({exc})") from None
    z, e = d["0th"], d["Exif"]

    def rat(v):
        return v[0] / v[1] if v else None

    return {
        "make": z.get(piexif.ImageIFD.Make, b"").decode(),
        "model": z.get(piexif.ImageIFD.Model, b"").decode(),
        "focal_length_mm": rat(e.get(piexif.ExifIFD.FocalLength)),
        "focal_length_35mm": e.get(piexif.ExifIFD.FocalLengthIn35mmFilm),
        "focal_plane_x_res_px_per_cm": rat(e.get(piexif.ExifIFD.FocalPlaneXResolution)),
        "datetime_original": e.get(piexif.ExifIFD.DateTimeOriginal, b"").decode(),
        "width": e.get(piexif.ExifIFD.PixelXDimension),
        "height": e.get(piexif.ExifIFD.PixelYDimension),
    }
