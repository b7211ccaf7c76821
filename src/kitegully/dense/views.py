"""Calibrated, oriented images for dense matching, and their image pyramids.

Conventions follow COLMAP (and :mod:`kitegully.twin.camera`): ``X_cam = R (X_world − C)``,
camera x to the image right, y down, z along the optical axis; pixel centres at integer
coordinates; ``RADIAL`` distortion ``x_d = x (1 + k1 r² + k2 r⁴)`` on normalised
coordinates. World coordinates are *local*: site CRS minus an offset (see
:class:`ViewSet`), so that float32 sums stay precise with UTM coordinates.

Pyramid level ``s`` is made of 2×2 block means, so a level-0 pixel coordinate ``u`` maps
to ``(u + 0.5) / 2**s − 0.5`` at level ``s``.
"""

from __future__ import annotations

import json
from collections import OrderedDict
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from kitegully import InputError

if TYPE_CHECKING:
    import pycolmap


@dataclass(frozen=True)
class OrientedImage:
    """One calibrated, oriented image.

    Attributes
    ----------
    name : str
        Image name (as in the SfM model).
    path : str
        Image file.
    width, height : int
        Image size (px).
    f, cx, cy, k1, k2 : float
        Intrinsics in pixels (``RADIAL`` model; pinhole when ``k1 = k2 = 0``).
    R : (3, 3) ndarray
        Rotation world → camera.
    C : (3,) ndarray
        Projection centre in *local* coordinates (site CRS minus the view set's offset).
    """

    name: str
    path: str
    width: int
    height: int
    f: float
    cx: float
    cy: float
    k1: float
    k2: float
    R: np.ndarray
    C: np.ndarray

    def project(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Pixel coordinates ``(u, v)`` and depth of local points ``X`` (..., 3)."""
        Xc = (np.asarray(X, float) - self.C) @ self.R.T
        z = Xc[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            x = Xc[..., 0] / z
            y = Xc[..., 1] / z
        r2 = x * x + y * y
        d = 1.0 + self.k1 * r2 + self.k2 * r2 * r2
        return self.f * x * d + self.cx, self.f * y * d + self.cy, z

    def gsd_at(self, z_ground: float) -> float:
        """Nadir ground sampling distance (m) over a ground at local height ``z_ground``."""
        return abs(float(self.C[2]) - z_ground) / self.f

    def params(self) -> np.ndarray:
        """``(f, cx, cy, k1, k2)`` as float64, for the compiled kernels."""
        return np.array([self.f, self.cx, self.cy, self.k1, self.k2], dtype=np.float64)


@dataclass
class ViewSet:
    """Oriented images plus the offset between local and site coordinates.

    ``site = local + offset``. ``sparse_points`` (N, 3) local tie points, used to bound the
    elevation search (may be empty).
    """

    images: list[OrientedImage]
    offset: np.ndarray = field(default_factory=lambda: np.zeros(3))
    sparse_points: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))

    def to_local(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Site map coordinates ``(x, y)`` in the local frame: ``local = site − offset``."""
        return np.asarray(x, float) - self.offset[0], np.asarray(y, float) - self.offset[1]


def _intrinsics(cam, where: str) -> tuple[float, float, float, float, float]:
    p = np.asarray(cam.params, float)
    name = cam.model.name
    if name == "SIMPLE_PINHOLE":
        return p[0], p[1], p[2], 0.0, 0.0
    if name == "PINHOLE":
        if abs(p[0] - p[1]) > 1e-6 * p[0]:
            raise InputError(f"{where}: PINHOLE camera with fx != fy is not supported (square pixels expected)")
        return p[0], p[2], p[3], 0.0, 0.0
    if name == "SIMPLE_RADIAL":
        return p[0], p[1], p[2], p[3], 0.0
    if name == "RADIAL":
        return p[0], p[1], p[2], p[3], p[4]
    raise InputError(f"{where}: camera model {name} is not supported (use SIMPLE_PINHOLE, SIMPLE_RADIAL or RADIAL)")


def read_offset(transform_json: str | Path | None) -> np.ndarray:
    """Offset of a georeferenced model's local frame (site = model + offset).

    Reads ``offset_m`` (three numbers) from the georeferencing stage's ``transform.json``;
    ``None`` means the model is already in site coordinates (offset 0).
    """
    if transform_json is None:
        return np.zeros(3)
    path = Path(transform_json)
    try:
        obj = json.loads(path.read_text(encoding="utf-8"))
        off = np.asarray(obj["offset_m"], dtype=float)
        if off.shape != (3,) or not np.all(np.isfinite(off)):
            raise ValueError
    except OSError as exc:
        raise InputError(f"{path}: cannot read the georeferencing transform ({exc})") from None
    except (ValueError, KeyError, TypeError):
        raise InputError(f"{path}: expected a key offset_m with three finite numbers (site = model + offset)") from None
    return off


def views_from_reconstruction(rec: pycolmap.Reconstruction, image_dir: str | Path,
                              model_offset: np.ndarray | None = None, local_offset: np.ndarray | None = None,
                              where: str = "model") -> ViewSet:
    """Oriented images of a ``pycolmap.Reconstruction`` (pycolmap 4.x API).

    Parameters
    ----------
    rec
        The reconstruction; its coordinates are site CRS minus ``model_offset``.
    image_dir
        Folder holding the images named as in the model.
    model_offset
        Offset of the model's coordinates (default 0: the model is in site coordinates).
    local_offset
        Offset of the local frame used for matching; default: the rounded mean of the
        camera centres (so local coordinates stay small whatever the CRS).
    """
    model_offset = np.zeros(3) if model_offset is None else np.asarray(model_offset, float)
    ids = sorted(int(i) for i in rec.reg_image_ids())
    if len(ids) < 2:
        raise InputError(f"{where}: {len(ids)} registered image(s); dense matching needs at least two")
    Rs, Cs, rows = [], [], []
    for i in ids:
        img = rec.images[i]
        cam = rec.cameras[int(img.camera_id)]
        f, cx, cy, k1, k2 = _intrinsics(cam, where)
        pose = img.cam_from_world()
        R = np.asarray(pose.rotation.matrix(), float)
        t = np.asarray(pose.translation, float).reshape(3)
        C = -R.T @ t + model_offset
        Rs.append(R)
        Cs.append(C)
        rows.append((img.name, int(cam.width), int(cam.height), f, cx, cy, k1, k2))
    Cs = np.asarray(Cs)
    if local_offset is None:
        local_offset = np.round(Cs.mean(axis=0), 0)
        local_offset[2] = 0.0
    local_offset = np.asarray(local_offset, float)
    image_dir = Path(image_dir)
    images = []
    for (name, w, h, f, cx, cy, k1, k2), R, C in zip(rows, Rs, Cs):
        images.append(OrientedImage(name, str(image_dir / name), w, h, f, cx, cy, k1, k2, R, C - local_offset))
    pts = [np.asarray(p.xyz, float) for p in rec.points3D.values()]
    sparse = (np.asarray(pts) + model_offset - local_offset) if pts else np.zeros((0, 3))
    return ViewSet(images, local_offset, sparse)


def shift_views(views: ViewSet, new_offset: np.ndarray) -> ViewSet:
    """The same views expressed with another local offset."""
    d = views.offset - np.asarray(new_offset, float)
    imgs = [replace(v, C=v.C + d) for v in views.images]
    return ViewSet(imgs, np.asarray(new_offset, float), views.sparse_points + d)


# --------------------------------------------------------------------------- pyramids


def downsample2(img: np.ndarray) -> np.ndarray:
    """2×2 block mean (odd trailing row/column dropped). Works on (H, W) or (H, W, B)."""
    h, w = img.shape[0] // 2 * 2, img.shape[1] // 2 * 2
    a = img[:h, :w].astype(np.float32, copy=False)
    return 0.25 * (a[0::2, 0::2] + a[1::2, 0::2] + a[0::2, 1::2] + a[1::2, 1::2])


def load_image(path: str | Path) -> np.ndarray:
    """An image as float32 (H, W, B) in 0–255; PNG, JPEG or TIFF (8 or 16 bit)."""
    import cv2

    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: image file not found")
    arr = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if arr is None:
        raise InputError(f"{path}: cannot decode image (corrupt or unsupported format)")
    scale = 255.0 / 65535.0 if arr.dtype == np.uint16 else 1.0
    if arr.ndim == 2:
        arr = arr[:, :, None]
    elif arr.shape[2] >= 3:
        # OpenCV reads BGR(A); keep R, G, B (+ a 4th band, e.g. NIR, if present).
        arr = np.concatenate([arr[:, :, 2::-1], arr[:, :, 3:]], axis=2)
    return arr.astype(np.float32) * np.float32(scale)


def grey(img: np.ndarray) -> np.ndarray:
    """Luminance of an (H, W, B) image (first three bands, or the single band)."""
    if img.shape[2] >= 3:
        return np.ascontiguousarray(0.299 * img[:, :, 0] + 0.587 * img[:, :, 1] + 0.114 * img[:, :, 2], dtype=np.float32)
    return np.ascontiguousarray(img[:, :, 0], dtype=np.float32)


class PyramidCache:
    """Least-recently-used cache of image pyramids (greyscale, optionally colour).

    ``level(i, s, colour)`` returns the pyramid level ``s`` of image ``i``. At most
    ``max_images`` images are kept, which bounds memory whatever the number of photos;
    levels finer than ``min_level`` (the finest the caller needs) are not kept.
    Images may also be given in memory (``arrays``), e.g. by tests.
    """

    def __init__(self, views: ViewSet, max_images: int = 32, arrays: list[np.ndarray] | None = None,
                 min_level: int = 0):
        self.views = views
        self.min_level = max(0, int(min_level))
        self.max_images = max(1, int(max_images))
        self.arrays = arrays
        self._cache: OrderedDict[tuple[int, bool], list[np.ndarray | None]] = OrderedDict()

    def _base(self, i: int) -> np.ndarray:
        if self.arrays is not None:
            a = np.asarray(self.arrays[i], dtype=np.float32)
            return a[:, :, None] if a.ndim == 2 else a
        img = load_image(self.views.images[i].path)
        v = self.views.images[i]
        if img.shape[:2] != (v.height, v.width):
            raise InputError(f"{v.path}: image is {img.shape[1]}x{img.shape[0]} px but the model says {v.width}x{v.height}")
        return img

    def level(self, i: int, s: int, colour: bool = False) -> np.ndarray:
        """Pyramid level ``s`` of image ``i`` (grey, or all bands with ``colour``).

        Levels finer than ``min_level`` are dropped after the pyramid is built (an image
        is re-read in the rare case such a level is asked for), so a cached image costs
        little more than the levels in use.

        Parameters
        ----------
        i : int
            Index of the image in ``views.images`` (or in ``arrays``).
        s : int
            Pyramid level (0 = full resolution, each level 2×2 block means of the one below).
        colour : bool
            All bands instead of the luminance.

        Returns
        -------
        ndarray (h, w) float32, or (h, w, B) float32 with ``colour``
            The level (0–255 for images read from file).
        """
        key = (i, colour)
        pyr = self._cache.get(key)
        if pyr is None or pyr[min(s, len(pyr) - 1)] is None:
            base = self._base(i)
            pyr = [np.ascontiguousarray(base if colour else grey(base), dtype=np.float32)]
            self._cache[key] = pyr
            while len(self._cache) > self.max_images:
                self._cache.popitem(last=False)
        else:
            self._cache.move_to_end(key)
        while len(pyr) <= s:
            pyr.append(np.ascontiguousarray(downsample2(pyr[-1])))
        for j in range(min(self.min_level, len(pyr) - 1)):
            pyr[j] = None
        return pyr[s]
