"""Reading photographs with their EXIF orientation and preparing them for SfM.

Pixel frames
------------
A camera stores its pixels in the *stored* (sensor) frame; the EXIF ``Orientation``
tag (values 1–8) says how a viewer turns them into the *display* frame. A kite
camera has one fixed lens, so its distortion and principal point belong to the
sensor frame: by default (``frame="stored"``) SfM runs on the stored pixels and
every image shares one camera even when some files carry a rotation tag and others
do not. With ``frame="display"`` the images are turned upright first and one
camera is shared per image shape.

Every pixel coordinate that enters the pipeline from outside (GCP observations) is
mapped into the SfM frame with :func:`to_sfm_pixels`, which knows the image's
orientation tag and scale, so the tag is applied consistently everywhere.
"""

from __future__ import annotations

import logging
from dataclasses import asdict, dataclass
from datetime import datetime
from pathlib import Path

import numpy as np
import piexif
from PIL import Image

from kitegully import InputError

log = logging.getLogger(__name__)

IMAGE_SUFFIXES = (".jpg", ".jpeg", ".tif", ".tiff", ".png")


@dataclass
class ImageInfo:
    """What the pipeline knows about one photograph.

    Attributes
    ----------
    name : str
        File name in the input folder (the name GCP files use).
    sfm_name : str
        File name of the prepared copy that COLMAP reads (capture-order prefix).
    orientation : int
        EXIF orientation tag (1 when absent).
    stored_width, stored_height : int
        Size of the stored pixel array (px).
    sfm_width, sfm_height : int
        Size of the prepared copy (px), in the SfM frame.
    scale : float
        SfM pixels per stored pixel (≤ 1).
    capture_time : str
        EXIF DateTimeOriginal in ISO form, or "" when absent.
    focal_px : float
        Focal length prior in SfM pixels from EXIF, NaN when EXIF lacks it.
    camera : str
        EXIF ``Make Model`` ("" when absent): with the pixel size it puts the image in a
        camera group that SfM calibrates on its own.
    """

    name: str
    sfm_name: str
    orientation: int
    stored_width: int
    stored_height: int
    sfm_width: int
    sfm_height: int
    scale: float
    capture_time: str
    focal_px: float
    camera: str = ""

    def as_row(self) -> dict:
        """The fields as a dict: one row of the image table."""
        return asdict(self)


def list_images(folder: str | Path) -> list[Path]:
    """Image files (JPEG/TIFF/PNG) in ``folder``, sorted by name; InputError when none."""
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(f"{folder}: image folder not found")
    files = sorted(p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    if not files:
        raise InputError(f"{folder}: no JPEG/TIFF/PNG images in the folder")
    return files


def _exif(path: Path) -> dict:
    try:
        return piexif.load(str(path))
    except Exception:  # piexif raises several types on files without EXIF (PNG, TIFF)
        return {"0th": {}, "Exif": {}}


def _rational(value) -> float:
    if value is None:
        return float("nan")
    if isinstance(value, tuple) and len(value) == 2:
        return value[0] / value[1] if value[1] else float("nan")
    return float(value)


def exif_orientation(path: str | Path) -> int:
    """EXIF orientation tag of an image (1 when absent or invalid)."""
    value = _exif(Path(path)).get("0th", {}).get(piexif.ImageIFD.Orientation, 1)
    return int(value) if value in range(1, 9) else 1


def focal_length_px(exif: dict, stored_width: int, stored_height: int) -> float:
    """Focal length in stored pixels from EXIF, NaN when it cannot be derived.

    Uses FocalLength with FocalPlaneXResolution (and its unit) when present, otherwise
    the 35 mm equivalent focal length against a 36 mm wide frame.

    Parameters
    ----------
    exif : dict
        The image's EXIF as :func:`piexif.load` returns it.
    stored_width, stored_height : int
        Size of the stored pixel array (px); the longer side is the 36 mm frame width.

    Returns
    -------
    float
        Focal length (stored px), NaN when EXIF lacks it.
    """
    ex = exif.get("Exif", {})
    f_mm = _rational(ex.get(piexif.ExifIFD.FocalLength))
    res = _rational(ex.get(piexif.ExifIFD.FocalPlaneXResolution))
    unit = ex.get(piexif.ExifIFD.FocalPlaneResolutionUnit, 2)
    unit_mm = {2: 25.4, 3: 10.0, 4: 1.0}.get(unit)
    if np.isfinite(f_mm) and np.isfinite(res) and res > 0 and unit_mm:
        return f_mm * res / unit_mm
    f35 = ex.get(piexif.ExifIFD.FocalLengthIn35mmFilm)
    if f35:
        return float(f35) / 36.0 * max(stored_width, stored_height)
    return float("nan")


def exif_camera(exif: dict) -> str:
    """``Make Model`` from EXIF (the make left out when the model repeats it); "" when absent."""
    zeroth = exif.get("0th", {}) or {}
    make = zeroth.get(piexif.ImageIFD.Make, b"").decode("ascii", "replace").strip("\x00 ")
    model = zeroth.get(piexif.ImageIFD.Model, b"").decode("ascii", "replace").strip("\x00 ")
    if make and model.lower().startswith(make.lower()):
        make = ""
    return " ".join(p for p in (make, model) if p)


def _capture_time(exif: dict) -> str:
    raw = exif.get("Exif", {}).get(piexif.ExifIFD.DateTimeOriginal)
    if not raw:
        return ""
    try:
        return datetime.strptime(raw.decode("ascii", "replace").strip("\x00 "), "%Y:%m:%d %H:%M:%S").isoformat()
    except ValueError:
        return ""


def read_image(path: str | Path, frame: str = "stored") -> np.ndarray:
    """Read an image as an RGB uint8 array in the stored or display frame.

    Raises
    ------
    InputError
        When the file cannot be decoded completely (corrupt or truncated).
    """
    path = Path(path)
    try:
        with Image.open(path) as im:
            im.load()
            rgb = im.convert("RGB")
    except Exception as exc:  # PIL raises OSError, SyntaxError, ValueError... on bad files
        raise InputError(f"{path}: cannot read image ({exc})") from None
    if frame == "display":
        rgb = _apply_orientation(rgb, exif_orientation(path))
    return np.asarray(rgb)


def display_size(orientation: int, width: int, height: int) -> tuple[int, int]:
    """(width, height) of the display frame for a stored size and orientation tag.

    Parameters
    ----------
    orientation : int
        EXIF orientation tag (1–8).
    width, height : int
        Stored size (px).

    Returns
    -------
    width, height : int
        Display size (px): swapped for tags 5–8.
    """
    return (height, width) if orientation in (5, 6, 7, 8) else (width, height)


def display_to_stored(xy: np.ndarray, orientation: int, width: int, height: int) -> np.ndarray:
    """Map pixel coordinates from the display frame to the stored frame.

    Coordinates are continuous pixel positions (0 at the left/top edge of the first
    pixel). ``width``, ``height`` are the stored size. O(n).

    Parameters
    ----------
    xy : ndarray (n, 2)
        Display-frame pixel coordinates (px).
    orientation : int
        EXIF orientation tag (1–8).
    width, height : int
        Stored size (px).

    Returns
    -------
    ndarray (n, 2) float
        Stored-frame pixel coordinates (px).
    """
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    x, y = xy[:, 0], xy[:, 1]
    W, H = width, height
    # For each tag: the stored position whose pixel shows up at display (x, y).
    table = {
        1: (x, y),
        2: (W - x, y),
        3: (W - x, H - y),
        4: (x, H - y),
        5: (y, x),
        6: (y, H - x),
        7: (W - y, H - x),
        8: (W - y, x),
    }
    sx, sy = table[orientation]
    return np.column_stack([sx, sy])


def stored_to_display(xy: np.ndarray, orientation: int, width: int, height: int) -> np.ndarray:
    """Inverse of :func:`display_to_stored` (``width``, ``height`` are the stored size). O(n).

    Parameters
    ----------
    xy : ndarray (n, 2)
        Stored-frame pixel coordinates (px).
    orientation : int
        EXIF orientation tag (1–8).
    width, height : int
        Stored size (px).

    Returns
    -------
    ndarray (n, 2) float
        Display-frame pixel coordinates (px).
    """
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    x, y = xy[:, 0], xy[:, 1]
    W, H = width, height
    table = {
        1: (x, y),
        2: (W - x, y),
        3: (W - x, H - y),
        4: (x, H - y),
        5: (y, x),
        6: (H - y, x),
        7: (H - y, W - x),
        8: (y, W - x),
    }
    dx, dy = table[orientation]
    return np.column_stack([dx, dy])


def to_sfm_pixels(xy: np.ndarray, info: ImageInfo, file_frame: str, sfm_frame: str, file_scale: float = 1.0) -> np.ndarray:
    """Map pixel coordinates measured in an input file's frame to the SfM frame.

    Parameters
    ----------
    xy
        (n, 2) pixel coordinates as written in the file.
    info
        The image's :class:`ImageInfo`.
    file_frame
        ``"stored"`` or ``"display"``: the frame the coordinates were measured in.
    sfm_frame
        The frame SfM ran in (``sfm.image_frame``).
    file_scale
        Pixels of the file's frame per full-resolution pixel (1 when the measurements
        were taken on the full-size image).
    """
    xy = np.asarray(xy, dtype=float).reshape(-1, 2) / file_scale
    W, H = info.stored_width, info.stored_height
    if file_frame == "display":
        xy = display_to_stored(xy, info.orientation, W, H)
    if sfm_frame == "display":
        xy = stored_to_display(xy, info.orientation, W, H)
    return xy * info.scale


def prepare_images(
    files: list[Path],
    out_dir: str | Path,
    max_image_size: int,
    frame: str = "stored",
    skip_unreadable: bool = False,
    jpeg_quality: int = 95,
) -> list[ImageInfo]:
    """Decode every image, downscale it and write the copy SfM reads.

    Images are ordered by EXIF capture time (then name) and written as
    ``<index>_<stem>.jpg`` so COLMAP's name order is the capture order (what sequential
    matching needs). Copies carry no orientation tag: their pixels are already in the
    SfM frame. Time O(total pixels); memory one image at a time.

    Parameters
    ----------
    files : list of Path
        The input images.
    out_dir : path
        Folder of the prepared copies (created if needed).
    max_image_size : int
        Longest side of a copy (px); larger images are downscaled, none is enlarged; 0 or less = full size.
    frame : str
        ``"stored"`` (the sensor's pixels) or ``"display"`` (turned upright by the EXIF tag).
    skip_unreadable : bool
        Skip unreadable files with a warning instead of raising.
    jpeg_quality : int
        JPEG quality of the copies (0–100).

    Returns
    -------
    list of ImageInfo
        One per prepared image, in capture order.

    Raises
    ------
    InputError
        Listing every unreadable file in one sentence, unless ``skip_unreadable`` (then
        a warning names them).
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    meta, bad = [], []
    for path in files:
        exif = _exif(path)
        try:
            with Image.open(path) as im:
                w, h = im.size
                im.verify()
        except Exception as exc:  # any decoder error means the file is unusable
            bad.append(f"{path.name} ({exc})")
            continue
        meta.append((_capture_time(exif), path.name, path, exif, w, h))
    meta.sort(key=lambda m: (m[0] or "9999", m[1]))
    infos = []
    for idx, (ctime, name, path, exif, w, h) in enumerate(meta):
        try:
            with Image.open(path) as im:
                im.load()
                im = im.convert("RGB")
        except Exception as exc:  # truncated data shows up only on full decode
            bad.append(f"{name} ({exc})")
            continue
        orient = exif_orientation(path)
        if frame == "display":
            im = _apply_orientation(im, orient)
        scale = min(1.0, max_image_size / max(w, h)) if max_image_size > 0 else 1.0
        if scale < 1.0:
            im = im.resize((round(im.width * scale), round(im.height * scale)), Image.Resampling.LANCZOS)
        sfm_name = f"{idx:04d}_{Path(name).stem}.jpg"
        im.save(out_dir / sfm_name, quality=jpeg_quality)
        # the scale actually applied (rounding of the size)
        scale_eff = im.width / (display_size(orient, w, h)[0] if frame == "display" else w)
        infos.append(
            ImageInfo(
                name=name,
                sfm_name=sfm_name,
                orientation=orient,
                stored_width=w,
                stored_height=h,
                sfm_width=im.width,
                sfm_height=im.height,
                scale=scale_eff,
                capture_time=ctime,
                focal_px=focal_length_px(exif, w, h) * scale_eff,
                camera=exif_camera(exif),
            )
        )
        log.info("prepared %s -> %s (%dx%d, orientation %d)", name, sfm_name, im.width, im.height, orient)
    if bad:
        msg = f"{Path(files[0]).parent}: unreadable or truncated images: {', '.join(bad)}"
        if not skip_unreadable:
            raise InputError(msg)
        log.warning("%s; skipped as sfm.skip_unreadable is true", msg)
    if len(infos) < 2:
        raise InputError(f"{Path(files[0]).parent}: fewer than two readable images")
    return infos


def _apply_orientation(im: Image.Image, orientation: int) -> Image.Image:
    """Turn a stored-frame image into the display frame (PIL transpose per EXIF tag)."""
    T = Image.Transpose
    ops = {
        1: [],
        2: [T.FLIP_LEFT_RIGHT],
        3: [T.ROTATE_180],
        4: [T.FLIP_TOP_BOTTOM],
        5: [T.TRANSPOSE],
        6: [T.ROTATE_270],
        7: [T.TRANSVERSE],
        8: [T.ROTATE_90],
    }
    for op in ops[orientation]:
        im = im.transpose(op)
    return im
